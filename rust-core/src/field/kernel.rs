//! Radially symmetric SPH kernels, normalised in 3D, with exact radial derivatives.
//!
//! Every kernel takes the smoothing length `h`; its support radius is `support_factor() * h`.
//! Conventions follow the literature each kernel comes from, so an `h` read from a solver's
//! output means what the solver meant: cubic spline (Monaghan's M4, support 2h, used by
//! SPlisHSPlasH and splashsurf), Wendland C2 (support 2h, DualSPHysics' "Wendland"),
//! quintic spline (Morris, support 3h) and the quadratic kernel of Johnson et al.
//! (support 2h, the paper's tsunami data).

use std::f64::consts::PI;
use std::str::FromStr;

/// The kernels the core knows.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Kernel {
    /// Monaghan's M4 cubic spline, support 2h.
    CubicSpline,
    /// Wendland C2 (the "quintic Wendland" of DualSPHysics), support 2h.
    WendlandC2,
    /// Morris' quintic spline (M6), support 3h.
    QuinticSpline,
    /// Johnson et al.'s quadratic kernel, support 2h.
    Quadratic,
}

impl Kernel {
    /// Every kernel, for tests and help texts.
    pub const ALL: [Kernel; 4] = [
        Kernel::CubicSpline,
        Kernel::WendlandC2,
        Kernel::QuinticSpline,
        Kernel::Quadratic,
    ];

    /// Support radius in units of h.
    pub fn support_factor(self) -> f64 {
        match self {
            Kernel::QuinticSpline => 3.0,
            _ => 2.0,
        }
    }

    /// How far (as a fraction of the support) a lone particle's level set W(r)/W(0) = f
    /// can lie from the linear estimate r = (1 − f)·support, over all f in (0, 1): the
    /// kernel's departure from a straight line. Seeding uses it to size its windows.
    pub fn linear_crossing_error(self) -> f64 {
        match self {
            Kernel::CubicSpline => 0.273,
            Kernel::WendlandC2 => 0.319,
            Kernel::QuinticSpline => 0.389,
            Kernel::Quadratic => 0.251,
        }
    }

    /// Name used on command lines and in files.
    pub fn name(self) -> &'static str {
        match self {
            Kernel::CubicSpline => "cubic",
            Kernel::WendlandC2 => "wendland",
            Kernel::QuinticSpline => "quintic",
            Kernel::Quadratic => "quadratic",
        }
    }

    /// Normalisation constant times h^3.
    pub(crate) fn sigma(self) -> f64 {
        match self {
            Kernel::CubicSpline => 1.0 / PI,
            Kernel::WendlandC2 => 21.0 / (16.0 * PI),
            Kernel::QuinticSpline => 1.0 / (120.0 * PI),
            Kernel::Quadratic => 15.0 / (16.0 * PI),
        }
    }

    /// Shape f(q) and its derivative f'(q), without normalisation, for q = r/h >= 0;
    /// zero from the support on.
    #[inline(always)]
    pub(crate) fn shape(self, q: f64) -> (f64, f64) {
        if q < self.support_factor() {
            self.shape_in_support(q)
        } else {
            (0.0, 0.0)
        }
    }

    /// (f(q), f'(q)) for 0 <= q < support factor, every piece evaluated and one selected
    /// (a past piece of the quintic contributes coef · 0): no branch on q, which in the
    /// SPH sums falls on either side of a piece's edge at random. Beyond the support the
    /// result is meaningless: [`Kernel::shape`] and the row lanes mask it.
    #[inline(always)]
    pub(crate) fn shape_in_support(self, q: f64) -> (f64, f64) {
        match self {
            Kernel::CubicSpline => {
                let inner = (1.0 - 1.5 * q * q + 0.75 * q * q * q, q * (-3.0 + 2.25 * q));
                let a = 2.0 - q;
                let outer = (0.25 * a * a * a, -0.75 * a * a);
                if q < 1.0 {
                    inner
                } else {
                    outer
                }
            }
            Kernel::WendlandC2 => {
                let a = 1.0 - 0.5 * q;
                let a3 = a * a * a;
                (a3 * a * (2.0 * q + 1.0), -5.0 * q * a3)
            }
            Kernel::QuinticSpline => {
                let (mut f, mut d) = (0.0, 0.0);
                for (edge, coef) in [(3.0, 1.0), (2.0, -6.0), (1.0, 15.0)] {
                    let a: f64 = (edge - q).max(0.0);
                    let a4 = a * a * a * a;
                    f += coef * a4 * a;
                    d -= 5.0 * coef * a4;
                }
                (f, d)
            }
            Kernel::Quadratic => (0.25 * q * q - q + 1.0, 0.5 * q - 1.0),
        }
    }

    /// W(r, h).
    #[inline(always)]
    pub fn value(self, r: f64, h: f64) -> f64 {
        let inv_h = 1.0 / h;
        self.sigma() * inv_h * inv_h * inv_h * self.shape(r * inv_h).0
    }

    /// (W(r, h), dW/dr(r, h)).
    #[inline(always)]
    pub fn value_and_derivative(self, r: f64, h: f64) -> (f64, f64) {
        let inv_h = 1.0 / h;
        let s = self.sigma() * inv_h * inv_h * inv_h;
        let (f, d) = self.shape(r * inv_h);
        (s * f, s * d * inv_h)
    }
}

impl FromStr for Kernel {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        match s.to_ascii_lowercase().as_str() {
            "cubic" | "cubic-spline" | "cubicspline" | "m4" => Ok(Kernel::CubicSpline),
            "wendland" | "wendland-c2" | "wendlandc2" => Ok(Kernel::WendlandC2),
            "quintic" | "quintic-spline" | "m6" => Ok(Kernel::QuinticSpline),
            "quadratic" => Ok(Kernel::Quadratic),
            _ => Err(format!(
                "unknown kernel '{s}' (known: cubic, wendland, quintic, quadratic)"
            )),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kernels_integrate_to_one() {
        for k in Kernel::ALL {
            for h in [0.5, 1.0, 0.037] {
                let rmax = k.support_factor() * h;
                let n = 200_000;
                let dr = rmax / n as f64;
                let integral: f64 = (0..n)
                    .map(|i| {
                        let r = (i as f64 + 0.5) * dr;
                        k.value(r, h) * 4.0 * PI * r * r * dr
                    })
                    .sum();
                assert!((integral - 1.0).abs() < 1e-6, "{k:?} h={h}: {integral}");
            }
        }
    }

    #[test]
    fn derivatives_match_finite_differences() {
        for k in Kernel::ALL {
            let h = 0.8;
            for i in 1..300 {
                let r = i as f64 / 300.0 * k.support_factor() * h;
                let e = 1e-6;
                let fd = (k.value(r + e, h) - k.value(r - e, h)) / (2.0 * e);
                let (_, d) = k.value_and_derivative(r, h);
                assert!(
                    (fd - d).abs() < 1e-6 * (1.0 + d.abs()),
                    "{k:?} r={r}: {fd} vs {d}"
                );
            }
        }
    }

    #[test]
    fn linear_crossing_error_bounds_every_isovalue() {
        for k in Kernel::ALL {
            let (h, support) = (1.0, k.support_factor());
            let mut worst = 0.0f64;
            for i in 1..1000 {
                let f = i as f64 / 1000.0;
                let (mut lo, mut hi) = (0.0, support);
                for _ in 0..60 {
                    let mid = 0.5 * (lo + hi);
                    if k.value(mid, h) > f * k.value(0.0, h) {
                        lo = mid;
                    } else {
                        hi = mid;
                    }
                }
                worst = worst.max((lo / support - (1.0 - f)).abs());
            }
            assert!(worst <= k.linear_crossing_error(), "{k:?}: {worst}");
            assert!(
                worst > k.linear_crossing_error() - 0.005,
                "{k:?}: bound {worst} is loose"
            );
        }
    }

    #[test]
    fn kernels_vanish_at_support_and_beyond() {
        for k in Kernel::ALL {
            let rs = k.support_factor() * 1.3;
            assert_eq!(k.value(rs, 1.3), 0.0);
            assert_eq!(k.value_and_derivative(rs * 1.5, 1.3), (0.0, 0.0));
            assert!(k.value(0.0, 1.3) > 0.0);
        }
    }
}
