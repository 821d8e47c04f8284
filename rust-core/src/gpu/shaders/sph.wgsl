// The SPH field of `field/sph.rs`, A(x) = sum_j V_j A_j W(x - x_j, h_j), in f32, summed
// in the CPU's order: neighbour-grid rows z, y, then the contiguous slot range of x.
// Positions are relative to the extraction grid's origin (subtracted in f64 on the CPU).

struct Particle {
    pos: vec3<f32>,
    support2: f32,
    inv_h: f32,
    weight_scale: f32,
    value: f32,
    pad: f32,
}

struct Field {
    origin: vec3<f32>,   // neighbour grid origin
    inv_cell: f32,
    dims: vec3<u32>,
    kernel: u32,         // 0 cubic, 1 Wendland C2, 2 quintic, 3 quadratic
    shepard: u32,
    reach: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<storage, read> particles: array<Particle>;
@group(0) @binding(1) var<storage, read> offsets: array<u32>;
@group(0) @binding(2) var<uniform> field: Field;

// (f(q), f'(q)) of `Kernel::shape`.
fn shape(q: f32) -> vec2<f32> {
    switch field.kernel {
        case 0u: {
            if q < 1.0 {
                return vec2<f32>(1.0 - 1.5 * q * q + 0.75 * q * q * q, q * (-3.0 + 2.25 * q));
            } else if q < 2.0 {
                let a = 2.0 - q;
                return vec2<f32>(0.25 * a * a * a, -0.75 * a * a);
            }
            return vec2<f32>(0.0);
        }
        case 1u: {
            if q < 2.0 {
                let a = 1.0 - 0.5 * q;
                let a3 = a * a * a;
                return vec2<f32>(a3 * a * (2.0 * q + 1.0), -5.0 * q * a3);
            }
            return vec2<f32>(0.0);
        }
        case 2u: {
            var f = 0.0;
            var d = 0.0;
            var edges = array<f32, 3>(3.0, 2.0, 1.0);
            var coefs = array<f32, 3>(1.0, -6.0, 15.0);
            for (var i = 0; i < 3; i++) {
                if q < edges[i] {
                    let a = edges[i] - q;
                    let a4 = a * a * a * a;
                    f += coefs[i] * a4 * a;
                    d -= 5.0 * coefs[i] * a4;
                }
            }
            return vec2<f32>(f, d);
        }
        default: {
            if q < 2.0 {
                return vec2<f32>(0.25 * q * q - q + 1.0, 0.5 * q - 1.0);
            }
            return vec2<f32>(0.0);
        }
    }
    return vec2<f32>(0.0);
}

// First and last neighbour-grid cells searched around x (`for_each_candidate_range`).
fn search_lo(x: vec3<f32>) -> vec3<i32> {
    let c = vec3<i32>(floor((x - field.origin) * field.inv_cell));
    return max(c - vec3<i32>(i32(field.reach)), vec3<i32>(0));
}

fn search_hi(x: vec3<f32>) -> vec3<i32> {
    let c = vec3<i32>(floor((x - field.origin) * field.inv_cell));
    return min(c + vec3<i32>(i32(field.reach)), vec3<i32>(field.dims) - vec3<i32>(1));
}

// (A, dA/dx, dA/dy, dA/dz) at x; the gradient only when `gradient`.
fn sph_sample(x: vec3<f32>, gradient: bool) -> vec4<f32> {
    let dims = vec3<i32>(field.dims);
    let lo = search_lo(x);
    let hi = search_hi(x);
    var a = 0.0;
    var s = 0.0;
    var ga = vec3<f32>(0.0);
    var gs = vec3<f32>(0.0);
    if any(lo > hi) {
        return vec4<f32>(0.0);
    }
    for (var z = lo.z; z <= hi.z; z++) {
        for (var y = lo.y; y <= hi.y; y++) {
            let row = dims.x * (y + dims.y * z);
            let start = offsets[u32(row + lo.x)];
            let end = offsets[u32(row + hi.x + 1)];
            for (var j = start; j < end; j++) {
                let p = particles[j];
                let d = x - p.pos;
                let r2 = dot(d, d);
                if r2 < p.support2 {
                    let r = sqrt(r2);
                    let f = shape(r * p.inv_h);
                    let w = p.weight_scale * f.x;
                    a += w * p.value;
                    s += w;
                    if gradient && r > 0.0 {
                        let g = d * (p.weight_scale * f.y * p.inv_h / r);
                        ga += g * p.value;
                        gs += g;
                    }
                }
            }
        }
    }
    if field.shepard != 0u {
        if s > 0.0 {
            let v = a / s;
            ga = (ga - gs * v) / s;
            a = v;
        } else {
            a = 0.0;
            ga = vec3<f32>(0.0);
        }
    }
    return vec4<f32>(a, ga);
}

fn field_value(x: vec3<f32>) -> f32 {
    return sph_sample(x, false).x;
}
