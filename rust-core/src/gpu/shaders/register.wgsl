// Particle registration (Algorithm 1, step 1; appended to sph.wgsl for `particles`):
// one invocation per particle finds its coarse cell and adds one to that cell's count
// with an atomic, as the paper does with atomicAdd.
//
// Exact without f64. The device holds x = f32(d), d = p - origin rounded once in f64 on
// the CPU, which is the very d the CPU registration divides. `thresholds` holds, per
// axis, t[k] = f32(T[k]) where T[k] is the smallest f64 d in coarse cell >= k (found on
// the CPU by bisection of its own cell function). Rounding to f32 is monotone, so
// x < t[k] proves d < T[k] and x > t[k] proves d >= T[k]: comparisons alone place the
// particle unless x == t[k] for some k (d within half an f32 ulp of a face). Those
// particles, and any outside the grid, are listed for the CPU to place in f64; nothing
// here rounds. A device that flushes subnormals to zero only merges values, which can
// turn a strict comparison into a tie (deferred), never reverse one.

struct Register {
    count: u32,      // particles
    cells_x: u32,
    cells_y: u32,
    cells_z: u32,
    base_x: u32,     // first threshold of each axis in `thresholds`
    base_y: u32,
    base_z: u32,
    total: u32,      // coarse cells; counts[total] is the deferred-particle counter
}

@group(0) @binding(3) var<uniform> reg: Register;
@group(0) @binding(4) var<storage, read> thresholds: array<f32>;
@group(0) @binding(5) var<storage, read_write> counts: array<atomic<u32>>;
@group(0) @binding(6) var<storage, read_write> deferred: array<u32>;

// The coarse coordinate of x along an axis of `n` cells whose thresholds start at
// `base`, or 0xffffffff when the comparisons cannot decide it (a tie, or outside).
fn axis_cell(x: f32, n: u32, base: u32) -> u32 {
    // Lower bound: the number of thresholds below x (t is non-decreasing).
    var lo = 0u;
    var hi = n + 1u;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if thresholds[base + mid] < x {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    // t[lo] >= x: equal is a tie. Otherwise T[0..lo] <= d < T[lo..], so the coordinate is
    // lo - 1, inside when 1 <= lo <= n. NaN compares false everywhere: lo = 0, deferred.
    if (lo <= n && thresholds[base + lo] == x) || lo == 0u || lo > n {
        return 0xffffffffu;
    }
    return lo - 1u;
}

@compute @workgroup_size(64)
fn register_particles(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let i = gid.x + gid.y * nwg.x * 64u;
    if i >= reg.count {
        return;
    }
    let x = particles[i].pos;
    let cx = axis_cell(x.x, reg.cells_x, reg.base_x);
    let cy = axis_cell(x.y, reg.cells_y, reg.base_y);
    let cz = axis_cell(x.z, reg.cells_z, reg.base_z);
    if cx == 0xffffffffu || cy == 0xffffffffu || cz == 0xffffffffu {
        deferred[atomicAdd(&counts[reg.total], 1u)] = i;
        return;
    }
    atomicAdd(&counts[cx + reg.cells_x * (cy + reg.cells_y * cz)], 1u);
}
