// Algorithm 2 of the adaptive 3-level method for the cells of one level (appended to
// sph.wgsl): vertex values, sub-cell cases with triangle and cut-edge counts, emission of
// cut edges and triangles at scanned offsets, bisection of the unique cut edges.
// Every point is a point of the bisection lattice, `sub * unit` from the grid origin with
// integer `sub` (finest node n: sub = n << shift), below 2^24 so f32 holds it exactly: a
// point has one f32 position, hence one value, whichever level or edge asks for it, and
// points shared by levels coincide as on the CPU. An edge is named by `mc::edge_key`
// split in two words (axis | x << 2 | y << 22 | z << 42).

struct Level {
    fine: f32,
    iso: f32,
    k: u32,          // sub-cells per axis
    step: u32,       // finest cells per sub-cell
    shift: u32,      // bisection lattice: 2^shift units per finest cell
    steps: u32,      // bisection halvings
    cells_x: u32,    // coarse cells per axis
    cells_y: u32,
    count: u32,      // invocations that do work
    normals: u32,
    unit: f32,       // fine / 2^shift
    margin: f32,     // values this close to iso are settled (gpu/sides.rs)
}

@group(0) @binding(3) var<uniform> level: Level;
@group(0) @binding(4) var<storage, read> cells: array<u32>;
@group(0) @binding(5) var<storage, read_write> values: array<f32>;
@group(0) @binding(6) var<storage, read_write> cases: array<u32>;
@group(0) @binding(7) var<storage, read_write> tri_offsets: array<u32>;
@group(0) @binding(8) var<storage, read_write> edge_offsets: array<u32>;
// [0, 256): triangles per case; [256, 512): cut-edge bits; 512 + 15 case + 3 t + j: edges.
@group(0) @binding(9) var<storage, read> table: array<u32>;
@group(0) @binding(10) var<storage, read_write> edges_out: array<vec4<u32>>;
@group(0) @binding(11) var<storage, read_write> tris_out: array<vec2<u32>>;
@group(0) @binding(12) var<storage, read> bisect_in: array<vec4<u32>>;
@group(0) @binding(13) var<storage, read_write> bisect_out: array<vec4<f32>>;
// Settled nodes (gpu/sides.rs): (node key low, high, value bits, 0) sorted by key, then a
// sentinel of all ones.
@group(0) @binding(23) var<storage, read> sides: array<vec4<u32>>;
// Word 0 counts the nodes met unsettled; their keys follow, two words each, as room allows.
@group(0) @binding(24) var<storage, read_write> pending: array<atomic<u32>>;

fn index_of(gid: vec3<u32>, nwg: vec3<u32>) -> u32 {
    return gid.x + gid.y * nwg.x * 64u;
}

fn coarse_coords(i: u32) -> vec3<u32> {
    return vec3<u32>(i % level.cells_x, i / level.cells_x % level.cells_y, i / (level.cells_x * level.cells_y));
}

fn local_coords(i: u32, n: u32) -> vec3<u32> {
    return vec3<u32>(i % n, i / n % n, i / (n * n));
}

fn corner_offset(c: u32) -> vec3<u32> {
    return vec3<u32>(c & 1u, (c >> 1u) & 1u, (c >> 2u) & 1u);
}

// (lower corner, axis) of local edge e, as `mc::edge_corner_axis`.
fn edge_corner_axis(e: u32) -> vec2<u32> {
    let a = e / 4u;
    let kk = e % 4u;
    let b = (a + 1u) % 3u;
    let c = (a + 2u) % 3u;
    return vec2<u32>(((kk & 1u) << b) | (((kk >> 1u) & 1u) << c), a);
}

fn value_index(slot: u32, l: vec3<u32>) -> u32 {
    let n = level.k + 1u;
    return slot * n * n * n + l.x + n * (l.y + n * l.z);
}

fn edge_key(node: vec3<u32>, axis: u32) -> vec2<u32> {
    return vec2<u32>(axis | (node.x << 2u) | ((node.y & 0x3FFu) << 22u), (node.y >> 10u) | (node.z << 10u));
}

// `mc::VirtualGrid::key` of a finest node in two words (x | y << 20 | z << 40).
fn node_key(node: vec3<u32>) -> vec2<u32> {
    return vec2<u32>(node.x | (node.y << 20u), (node.y >> 12u) | (node.z << 8u));
}

// The value at finest node `node` whose f32 evaluation gave `v`, on the CPU's side of
// the isovalue: `v` itself unless it lies within the margin, else the settled value, or
// `v` for now with the node put on the pending list.
fn settled(node: vec3<u32>, v: f32) -> f32 {
    if abs(v - level.iso) > level.margin {
        return v;
    }
    let key = node_key(node);
    var lo = 0u;
    var hi = arrayLength(&sides) - 1u;  // the sentinel is never a node
    while lo < hi {
        let mid = (lo + hi) / 2u;
        let e = sides[mid];
        if e.y < key.y || (e.y == key.y && e.x < key.x) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    let e = sides[lo];
    if e.x == key.x && e.y == key.y {
        return bitcast<f32>(e.z);
    }
    let slot = atomicAdd(&pending[0], 1u);
    if 2u * slot + 2u < arrayLength(&pending) {
        atomicStore(&pending[2u * slot + 1u], key.x);
        atomicStore(&pending[2u * slot + 2u], key.y);
    }
    return v;
}

// Finest node of entry `id` of `values`.
fn value_node(id: u32) -> vec3<u32> {
    let n = level.k + 1u;
    let nnn = n * n * n;
    return coarse_coords(cells[id / nnn]) * 4u + local_coords(id % nnn, n) * level.step;
}

@compute @workgroup_size(64)
fn node_values(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let id = index_of(gid, nwg);
    if id >= level.count {
        return;
    }
    let node = value_node(id);
    values[id] = settled(node, field_value(vec3<f32>(node << vec3<u32>(level.shift)) * level.unit));
}

// `node_values` again for the nodes settled since, without evaluating the field.
@compute @workgroup_size(64)
fn settle_values(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let id = index_of(gid, nwg);
    if id >= level.count {
        return;
    }
    values[id] = settled(value_node(id), values[id]);
}

@compute @workgroup_size(64)
fn cell_cases(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let id = index_of(gid, nwg);
    if id >= level.count {
        return;
    }
    let kk = level.k * level.k * level.k;
    let slot = id / kk;
    let l = local_coords(id % kk, level.k);
    var cs = 0u;
    for (var c = 0u; c < 8u; c++) {
        if values[value_index(slot, l + corner_offset(c))] > level.iso {
            cs |= 1u << c;
        }
    }
    cases[id] = cs;
    tri_offsets[id] = table[cs];
    edge_offsets[id] = countOneBits(table[256u + cs]);
}

@compute @workgroup_size(64)
fn emit(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let id = index_of(gid, nwg);
    if id >= level.count {
        return;
    }
    let kk = level.k * level.k * level.k;
    let slot = id / kk;
    let l = local_coords(id % kk, level.k);
    let base = coarse_coords(cells[slot]) * 4u + l * level.step;
    let cs = cases[id];
    let bits = table[256u + cs];
    var out = edge_offsets[id];
    for (var e = 0u; e < 12u; e++) {
        if ((bits >> e) & 1u) == 1u {
            let ca = edge_corner_axis(e);
            let o = corner_offset(ca.x);
            let key = edge_key(base + o * level.step, ca.y);
            let f0 = values[value_index(slot, l + o)];
            let f1 = values[value_index(slot, l + corner_offset(ca.x | (1u << ca.y)))];
            edges_out[out] = vec4<u32>(key, bitcast<u32>(f0), bitcast<u32>(f1));
            out += 1u;
        }
    }
    let first = tri_offsets[id];
    for (var t = 0u; t < table[cs]; t++) {
        for (var j = 0u; j < 3u; j++) {
            let ca = edge_corner_axis(table[512u + 15u * cs + 3u * t + j]);
            tris_out[3u * (first + t) + j] = edge_key(base + corner_offset(ca.x) * level.step, ca.y);
        }
    }
}

// Point along `axis` from finest node `node`, `t` bisection units out.
fn lattice_point(node: vec3<u32>, axis: u32, t: u32) -> vec3<f32> {
    var s = node << vec3<u32>(level.shift);
    s[axis] += t;
    return vec3<f32>(s) * level.unit;
}

@compute @workgroup_size(64)
fn bisect(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let id = index_of(gid, nwg);
    if id >= level.count {
        return;
    }
    let e = bisect_in[id];
    let axis = e.x & 3u;
    let node = vec3<u32>((e.x >> 2u) & 0xFFFFFu, (e.x >> 22u) | ((e.y & 0x3FFu) << 10u), e.y >> 10u);
    var lo = 0u;
    var hi = level.step << level.shift;
    var flo = bitcast<f32>(e.z);
    var fhi = bitcast<f32>(e.w);
    let lo_inside = flo > level.iso;
    for (var s = 0u; s < level.steps; s++) {
        let mid = (lo + hi) / 2;
        var fm = field_value(lattice_point(node, axis, mid));
        if (mid & ((1u << level.shift) - 1u)) == 0u {
            var on = node;
            on[axis] += mid >> level.shift;
            fm = settled(on, fm);
        }
        if (fm > level.iso) == lo_inside {
            lo = mid;
            flo = fm;
        } else {
            hi = mid;
            fhi = fm;
        }
    }
    var normal = vec3<f32>(0.0);
    if level.normals != 0u {
        let d = fhi - flo;
        var t = 0.5;
        if d != 0.0 {
            t = clamp((level.iso - flo) / d, 0.0, 1.0);
        }
        var x = lattice_point(node, axis, lo);
        x[axis] = (f32((node[axis] << level.shift) + lo) + t) * level.unit;
        let g = sph_sample(x, true).yzw;
        let len = length(g);
        if len > 0.0 && len < 3.0e38 {
            normal = -g / len;
        } else {
            normal = vec3<f32>(0.0, 0.0, 1.0);
        }
    }
    bisect_out[2u * id] = vec4<f32>(f32(lo), flo, fhi, 0.0);
    bisect_out[2u * id + 1u] = vec4<f32>(normal, 0.0);
}
