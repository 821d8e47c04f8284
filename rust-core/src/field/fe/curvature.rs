//! Principal curvatures of a level set from the field's gradient and Hessian (Kindlmann
//! et al. 2003, the paper's reference [18]).

use glam::{DMat3, DVec3};

/// Principal curvatures (κ1 ≥ κ2) of the level set through a point where the field has
/// gradient `g` and Hessian `h`; positive where the surface bends away from the gradient
/// (a sphere of radius R around a minimum has κ = 1/R). Zero for a vanishing gradient.
pub fn principal_curvatures(g: DVec3, h: DMat3) -> (f64, f64) {
    let len = g.length();
    if len <= 0.0 || !len.is_finite() {
        return (0.0, 0.0);
    }
    let n = g / len;
    // Shape operator in an orthonormal tangent basis (t1, t2): −(tᵢᵀ H tⱼ)/|g| with the
    // sign that makes a sphere around a minimum positive; a symmetric 2×2 eigenproblem
    // avoids the cancellation of the trace/Frobenius formula for nearly equal κ.
    let t1 = n.any_orthonormal_vector();
    let t2 = n.cross(t1);
    let a = t1.dot(h * t1) / len;
    let b = t1.dot(h * t2) / len;
    let d = t2.dot(h * t2) / len;
    let mean = 0.5 * (a + d);
    let disc = (0.25 * (a - d) * (a - d) + b * b).sqrt();
    (mean + disc, mean - disc)
}

/// Curvature magnitude D = sqrt(κ1² + κ2²) (the paper's eq. 6).
pub fn curvature_magnitude(g: DVec3, h: DMat3) -> f64 {
    let (a, b) = principal_curvatures(g, h);
    (a * a + b * b).sqrt()
}
