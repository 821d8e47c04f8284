// Neighbour candidates for Marching Correctors' seed cells (appended to sph.wgsl): every
// particle j != i within a conservatively enlarged side radius of particle i, found with
// the field's own neighbour grid. The CPU applies the exact f64 tests to these.

struct Seeds {
    count: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(3) var<uniform> seeds: Seeds;
@group(0) @binding(4) var<storage, read> radius2: array<f32>;
@group(0) @binding(5) var<storage, read_write> offsets_out: array<u32>;
@group(0) @binding(6) var<storage, read_write> found: array<u32>;

// Counts particle i's candidates; writes them from `first` when `write`.
fn candidates(i: u32, write: bool, first: u32) -> u32 {
    let x = particles[i].pos;
    let r2 = radius2[i];
    let dims = vec3<i32>(field.dims);
    let lo = search_lo(x);
    let hi = search_hi(x);
    var n = 0u;
    if any(lo > hi) {
        return 0u;
    }
    for (var z = lo.z; z <= hi.z; z++) {
        for (var y = lo.y; y <= hi.y; y++) {
            let row = dims.x * (y + dims.y * z);
            let start = offsets[u32(row + lo.x)];
            let end = offsets[u32(row + hi.x + 1)];
            for (var j = start; j < end; j++) {
                let d = particles[j].pos - x;
                if j != i && dot(d, d) < r2 {
                    if write {
                        found[first + n] = j;
                    }
                    n += 1u;
                }
            }
        }
    }
    return n;
}

@compute @workgroup_size(64)
fn count_candidates(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 64u;
    if i >= seeds.count {
        return;
    }
    offsets_out[i] = candidates(i, false, 0u);
}

@compute @workgroup_size(64)
fn write_candidates(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 64u;
    if i >= seeds.count {
        return;
    }
    candidates(i, true, offsets_out[i]);
}
