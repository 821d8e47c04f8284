//! The SPH field: A(x) = Σ_j V_j A_j W(x − x_j, h_j) with V_j = m_j/ρ_j, its gradient,
//! and the sum of weights S(x) = Σ_j V_j W(x − x_j, h_j), evaluated in one neighbour pass.

use super::kernel::Kernel;
use super::neighbours::NeighbourGrid;
use super::particles::ParticleData;
use super::{ScalarField, DEFAULT_MEMORY_BUDGET, TILE};
use crate::error::{Error, Result};
use crate::progress::{chunked, Progress};
use glam::DVec3;
use rayon::prelude::*;

/// Which per-particle quantity the field interpolates.
#[derive(Clone, Debug, PartialEq)]
pub enum Quantity {
    /// A_j = 1: the sum of weights, whose level sets are free surfaces (splashsurf's
    /// "iso threshold" surface when volumes are computed).
    SumOfWeights,
    /// A scalar array.
    Scalar(String),
    /// The Euclidean norm of a vector array.
    Magnitude(String),
    /// One component of a vector array.
    Component(String, usize),
}

impl Quantity {
    /// Parses `name`, `name:mag` / `|name|` or `name:K`; "SumOfWeights" selects the weights.
    pub fn parse(s: &str) -> Quantity {
        if s.eq_ignore_ascii_case("sumofweights") || s.eq_ignore_ascii_case("sum-of-weights") {
            return Quantity::SumOfWeights;
        }
        if let Some(inner) = s.strip_prefix('|').and_then(|t| t.strip_suffix('|')) {
            return Quantity::Magnitude(inner.to_string());
        }
        if let Some((name, suffix)) = s.rsplit_once(':') {
            if suffix.eq_ignore_ascii_case("mag") || suffix.eq_ignore_ascii_case("magnitude") {
                return Quantity::Magnitude(name.to_string());
            }
            if let Ok(k) = suffix.parse::<usize>() {
                return Quantity::Component(name.to_string(), k);
            }
        }
        Quantity::Scalar(s.to_string())
    }

    /// Per-particle values in original order.
    fn values(&self, data: &ParticleData) -> Result<Vec<f64>> {
        let n = data.len();
        match self {
            Quantity::SumOfWeights => Ok(vec![1.0; n]),
            Quantity::Scalar(name) => {
                let a = data.require(name)?;
                if a.components == 1 {
                    Ok(a.data.clone())
                } else {
                    Err(Error::InvalidInput(format!(
                        "array '{name}' has {} components; choose '{name}:mag' for its magnitude or '{name}:K' for component K",
                        a.components
                    )))
                }
            }
            Quantity::Magnitude(name) => {
                let a = data.require(name)?;
                Ok((0..n)
                    .map(|i| a.item(i).iter().map(|v| v * v).sum::<f64>().sqrt())
                    .collect())
            }
            Quantity::Component(name, k) => {
                let a = data.require(name)?;
                if *k >= a.components {
                    return Err(Error::InvalidInput(format!(
                        "array '{name}' has {} components, component {k} does not exist",
                        a.components
                    )));
                }
                Ok((0..n).map(|i| a.item(i)[*k]).collect())
            }
        }
    }
}

/// Where smoothing lengths come from.
#[derive(Clone, Debug, PartialEq)]
pub enum SmoothingLength {
    Constant(f64),
    Array(String),
}

/// Where particle masses come from.
#[derive(Clone, Debug, PartialEq)]
pub enum Mass {
    Constant(f64),
    Array(String),
}

/// Where particle volumes V_j = m_j/ρ_j come from.
#[derive(Clone, Debug, PartialEq)]
pub enum Volumes {
    /// ρ_j = Σ_k m_k W(x_j − x_k, h_j) computed here (splashsurf's convention); with equal
    /// masses V_j = 1/Σ_k W_jk, independent of the mass value.
    Computed { mass: Option<Mass> },
    /// A per-particle volume array.
    Array(String),
    /// Mass and a density array from the solver.
    MassDensity { mass: Mass, density: String },
}

/// How to build an SPH field from particle data.
#[derive(Clone, Debug, PartialEq)]
pub struct SphSettings {
    pub kernel: Kernel,
    pub smoothing_length: SmoothingLength,
    /// Multiplies every smoothing length (the paper's 1, 0.75, 0.5 for previews).
    pub h_scale: f64,
    pub volumes: Volumes,
    pub quantity: Quantity,
    /// Divide by the sum of weights (Shepard normalisation).
    pub shepard: bool,
    /// Bytes that extent-sized structures may take.
    pub memory_budget: u64,
}

impl Default for SphSettings {
    fn default() -> Self {
        SphSettings {
            kernel: Kernel::CubicSpline,
            smoothing_length: SmoothingLength::Array("h".into()),
            h_scale: 1.0,
            volumes: Volumes::Computed { mass: None },
            quantity: Quantity::SumOfWeights,
            shepard: false,
            memory_budget: DEFAULT_MEMORY_BUDGET,
        }
    }
}

/// Neighbour-grid cells searched on each side of a query point (cells are half a support).
const REACH: i64 = 2;

/// Points along x that [`SphField::values_on_row`] evaluates together.
pub(crate) const ROW: usize = 4;

/// Evaluates `$body` with `$k` a constant copy of `$kernel`: each kernel gets its own
/// instance of the loop, so `shape`'s `match` folds away instead of being taken for
/// every neighbour.
macro_rules! with_kernel {
    ($kernel:expr, $k:ident => $body:expr) => {
        match $kernel {
            Kernel::CubicSpline => {
                const $k: Kernel = Kernel::CubicSpline;
                $body
            }
            Kernel::WendlandC2 => {
                const $k: Kernel = Kernel::WendlandC2;
                $body
            }
            Kernel::QuinticSpline => {
                const $k: Kernel = Kernel::QuinticSpline;
                $body
            }
            Kernel::Quadratic => {
                const $k: Kernel = Kernel::Quadratic;
                $body
            }
        }
    };
}

pub mod carried;
pub(crate) mod nodes;
pub use nodes::NodeTiles;

/// One particle as the evaluation loop wants it, stored in neighbour-grid order.
#[derive(Clone, Copy, Debug)]
struct Packed {
    pos: DVec3,
    /// (support radius)²
    support2: f64,
    inv_h: f64,
    /// V_j σ / h_j³: the factor in front of the kernel shape.
    weight_scale: f64,
    value: f64,
}

/// Value, gradient, sum of weights and its gradient at one point.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct Sample {
    pub value: f64,
    pub gradient: DVec3,
    pub weight: f64,
    pub weight_gradient: DVec3,
}

/// An SPH field ready for evaluation.
#[derive(Clone, Debug)]
pub struct SphField {
    kernel: Kernel,
    shepard: bool,
    grid: NeighbourGrid,
    particles: Vec<Packed>,
    /// Smoothing lengths before `h_scale`, in grid order (seeding and the virtual grid
    /// are sized by the data's own h).
    h_unscaled: Vec<f64>,
    h_scale: f64,
    max_support: f64,
    /// Bounds of the particle positions.
    bounds: (DVec3, DVec3),
    /// Every particle's value is exactly 1 (the sum-of-weights field): Σ w·1 is Σ w to
    /// the bit, so the loops sum only the weights and copy them.
    unit_values: bool,
    /// What the data suggests went wrong without being an error, for every host to show.
    warnings: Vec<String>,
}

impl SphField {
    /// Validates `data` and `settings` and builds the field. Errors name the array and the
    /// first offending particle index.
    pub fn new(data: &ParticleData, settings: &SphSettings) -> Result<Self> {
        Self::build(data, settings, &mut Progress::none())
    }

    /// As [`SphField::new`], reporting progress (the density sum is the long part) and
    /// honouring a cancel.
    pub fn build(
        data: &ParticleData,
        settings: &SphSettings,
        progress: &mut Progress,
    ) -> Result<Self> {
        progress.phase("building field", 0.0, 1.0)?;
        data.validate()?;
        let n = data.len();
        if !(settings.h_scale > 0.0 && settings.h_scale.is_finite()) {
            return Err(Error::InvalidParameter {
                name: "h_scale",
                message: format!("must be positive, got {}", settings.h_scale),
            });
        }
        let h: Vec<f64> = match &settings.smoothing_length {
            SmoothingLength::Constant(h) if !(*h > 0.0 && h.is_finite()) => {
                return Err(Error::InvalidParameter {
                    name: "h",
                    message: format!("the smoothing length must be positive and finite, got {h}"),
                })
            }
            SmoothingLength::Constant(h) => vec![*h; n],
            SmoothingLength::Array(name) => scalar_array(data, name, "smoothing length")?,
        };
        check_positive(&h, "smoothing length")?;
        let values = settings.quantity.values(data)?;
        if let Some(i) = values.iter().position(|v| !v.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "field value of particle {i} is not finite ({})",
                values[i]
            )));
        }
        let kernel = settings.kernel;
        let support_factor = kernel.support_factor();
        let max_support =
            h.iter().fold(0.0f64, |m, &v| m.max(v)) * settings.h_scale * support_factor;
        // Cells of half the support, searched two cells out: the candidate block is
        // (5/2)³ ≈ 15.6 support volumes instead of 27 with support-sized cells.
        let mut grid = NeighbourGrid::build(
            &data.positions,
            0.5 * max_support,
            REACH,
            settings.memory_budget,
        )?;
        let order = grid.order();
        let sigma = kernel.sigma();
        let h_unscaled: Vec<f64> = order.iter().map(|&i| h[i as usize]).collect();
        let mut particles: Vec<Packed> = order
            .par_iter()
            .map(|&i| {
                let i = i as usize;
                let hs = h[i] * settings.h_scale;
                let inv_h = 1.0 / hs;
                Packed {
                    pos: data.positions[i],
                    support2: (support_factor * hs).powi(2),
                    inv_h,
                    weight_scale: sigma * inv_h * inv_h * inv_h,
                    value: values[i],
                }
            })
            .collect();

        let volumes: Vec<f64> = match &settings.volumes {
            Volumes::Array(name) => {
                let v = scalar_array(data, name, "volume")?;
                check_positive(&v, "volume")?;
                order.iter().map(|&i| v[i as usize]).collect()
            }
            Volumes::MassDensity { mass, density } => {
                let m = masses(data, mass)?;
                let rho = scalar_array(data, density, "density")?;
                check_positive(&rho, "density")?;
                order
                    .iter()
                    .map(|&i| m[i as usize] / rho[i as usize])
                    .collect()
            }
            Volumes::Computed { mass } => {
                let m_sorted: Option<Vec<f64>> = match mass {
                    None => None,
                    Some(spec) => {
                        let m = masses(data, spec)?;
                        Some(order.iter().map(|&i| m[i as usize]).collect())
                    }
                };
                // The grid and particles lent to a bare field for the density pass and
                // taken back after: copies of them were about 75 MB of fresh pages on a
                // 1.26 M-particle frame.
                let probe = SphField {
                    kernel,
                    shepard: false,
                    grid,
                    particles,
                    h_unscaled: Vec::new(),
                    h_scale: settings.h_scale,
                    max_support,
                    bounds: (DVec3::ZERO, DVec3::ZERO),
                    unit_values: false,
                    warnings: Vec::new(),
                };
                let slots: Vec<usize> = (0..n).collect();
                let volumes = chunked(&slots, progress, |part| {
                    part.par_iter()
                        .map(|&s| {
                            let x = probe.particles[s].pos;
                            let mut rho = 0.0;
                            probe.for_each_neighbour(x, |slot, p, r2| {
                                let w = p.weight_scale * kernel.shape(r2.sqrt() * p.inv_h).0;
                                rho += m_sorted.as_ref().map_or(1.0, |m| m[slot]) * w;
                            });
                            m_sorted.as_ref().map_or(1.0, |m| m[s]) / rho
                        })
                        .collect()
                })?;
                (grid, particles) = (probe.grid, probe.particles);
                volumes
            }
        };
        for (p, v) in particles.iter_mut().zip(&volumes) {
            p.weight_scale *= v;
        }
        if settings.shepard && settings.quantity == Quantity::SumOfWeights {
            // S / S: 1 wherever a particle reaches, 0 elsewhere. No isovalue has a
            // surface, and every grid factor would be blamed in turn. (An array that
            // happens to be 1 at these particles is data, not a setting: a rank's piece
            // or a frame may hold such values, and gets the empty surface's warning.)
            return Err(Error::InvalidParameter {
                name: "shepard",
                message: "Shepard normalisation divides the field by the sum of weights, and the \
                          field is the sum of weights: the result is 1 wherever a particle \
                          reaches, with no surface; turn Shepard off for the free surface, or \
                          choose a particle array as the field"
                    .into(),
            });
        }
        let unit_values = particles.iter().all(|p| p.value == 1.0);
        let bounds = super::neighbours::bounds(&data.positions);
        let warnings = support_spans_the_data(n, max_support, bounds, settings)
            .into_iter()
            .collect();
        Ok(SphField {
            kernel,
            shepard: settings.shepard,
            grid,
            h_unscaled,
            h_scale: settings.h_scale,
            max_support,
            bounds,
            unit_values,
            particles,
            warnings,
        })
    }

    /// Warnings about the data that are not errors (a kernel wider than the particle set),
    /// which extractions pass on in their stats.
    pub fn warnings(&self) -> &[String] {
        &self.warnings
    }

    /// Bounds of the particle positions.
    pub fn bounds(&self) -> (DVec3, DVec3) {
        self.bounds
    }

    /// Calls `f(slot, particle, r²)` for every particle whose support contains `x`.
    #[inline(always)]
    fn for_each_neighbour(&self, x: DVec3, mut f: impl FnMut(usize, &Packed, f64)) {
        for range in self.grid.candidate_ranges(x, REACH) {
            for (slot, p) in self.particles[range.clone()].iter().enumerate() {
                let r2 = (x - p.pos).length_squared();
                if r2 < p.support2 {
                    f(range.start + slot, p, r2);
                }
            }
        }
    }

    /// (A(x), S(x)): value and sum of weights, no gradients.
    #[inline]
    pub fn value_and_weight(&self, x: DVec3) -> (f64, f64) {
        if self.unit_values {
            with_kernel!(self.kernel, K => self.value_and_weight_with::<true>(K, x))
        } else {
            with_kernel!(self.kernel, K => self.value_and_weight_with::<false>(K, x))
        }
    }

    /// [`SphField::value_and_weight`] with the kernel known at compile time. The sums are
    /// plain locals in plain loops: behind a closure they lived in memory, stored back for
    /// every neighbour.
    #[inline(always)]
    fn value_and_weight_with<const UNIT: bool>(&self, kernel: Kernel, x: DVec3) -> (f64, f64) {
        let (mut a, mut s) = (0.0, 0.0);
        for range in self.grid.candidate_ranges(x, REACH) {
            for p in &self.particles[range] {
                let r2 = (x - p.pos).length_squared();
                if r2 < p.support2 {
                    let w = p.weight_scale * kernel.shape(r2.sqrt() * p.inv_h).0;
                    if !UNIT {
                        a += w * p.value;
                    }
                    s += w;
                }
            }
        }
        if UNIT {
            a = s;
        }
        (self.normalised(a, s), s)
    }

    /// (A, S) at the [`ROW`] points (xs[l], y, z), each to the bit what
    /// [`SphField::value_and_weight`] gives there.
    ///
    /// Node by node, a node scans its whole candidate block and keeps about one particle
    /// in four. A row of nodes along x shares one block only a little longer than a
    /// node's, each particle's y and z distances are computed once for the row, and the
    /// per-node work is the same few operations on [`ROW`] lanes, which compile to vector
    /// instructions. Each lane adds its particles in ascending slot order, as the node's
    /// own loop does, and adds exactly 0 for the block's particles outside its support,
    /// so the sums are the node-by-node sums to the bit.
    #[inline]
    pub fn values_on_row(&self, xs: [f64; ROW], y: f64, z: f64) -> [(f64, f64); ROW] {
        if self.unit_values {
            with_kernel!(self.kernel, K => self.values_on_row_with::<true>(K, xs, y, z))
        } else {
            with_kernel!(self.kernel, K => self.values_on_row_with::<false>(K, xs, y, z))
        }
    }

    #[inline(always)]
    fn values_on_row_with<const UNIT: bool>(
        &self,
        kernel: Kernel,
        xs: [f64; ROW],
        y: f64,
        z: f64,
    ) -> [(f64, f64); ROW] {
        let reach = self.max_support;
        let (x_lo, x_hi) = xs
            .iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &x| {
                (lo.min(x), hi.max(x))
            });
        let lo = DVec3::new(x_lo - reach, y - reach, z - reach);
        let hi = DVec3::new(x_hi + reach, y + reach, z + reach);
        let (mut a, mut s) = ([0.0f64; ROW], [0.0f64; ROW]);
        for range in self.grid.ranges_in_box(lo, hi) {
            for p in &self.particles[range] {
                let (dy, dz) = (y - p.pos.y, z - p.pos.z);
                let (dy2, dz2) = (dy * dy, dz * dz);
                // Each lane's r² = (dx² + dy²) + dz² is at least dy² + dz² in floating
                // point too, so the particle is out of every lane's support.
                if dy2 + dz2 >= p.support2 {
                    continue;
                }
                for l in 0..ROW {
                    let dx = xs[l] - p.pos.x;
                    let r2 = dx * dx + dy2 + dz2;
                    let w = p.weight_scale * kernel.shape_in_support(r2.sqrt() * p.inv_h).0;
                    let w = if r2 < p.support2 { w } else { 0.0 };
                    if !UNIT {
                        a[l] += w * p.value;
                    }
                    s[l] += w;
                }
            }
        }
        std::array::from_fn(|l| {
            let a = if UNIT { s[l] } else { a[l] };
            (self.normalised(a, s[l]), s[l])
        })
    }

    /// A from its sum Σ V_j A_j W and the sum of weights S: divided by S under Shepard
    /// normalisation (0 where no particle reaches).
    #[inline(always)]
    fn normalised(&self, a: f64, s: f64) -> f64 {
        match self.shepard {
            true if s > 0.0 => a / s,
            true => 0.0,
            false => a,
        }
    }

    /// Value, gradient, sum of weights and its gradient at `x`.
    #[inline]
    pub fn sample(&self, x: DVec3) -> Sample {
        if self.unit_values {
            with_kernel!(self.kernel, K => self.sample_with::<true>(K, x))
        } else {
            with_kernel!(self.kernel, K => self.sample_with::<false>(K, x))
        }
    }

    /// [`SphField::sample`] with the kernel known at compile time.
    #[inline(always)]
    fn sample_with<const UNIT: bool>(&self, kernel: Kernel, x: DVec3) -> Sample {
        let (mut a, mut s) = (0.0, 0.0);
        let (mut ga, mut gs) = (DVec3::ZERO, DVec3::ZERO);
        for range in self.grid.candidate_ranges(x, REACH) {
            for p in &self.particles[range] {
                let r2 = (x - p.pos).length_squared();
                if r2 < p.support2 {
                    let r = r2.sqrt();
                    let (f, df) = kernel.shape(r * p.inv_h);
                    let w = p.weight_scale * f;
                    if !UNIT {
                        a += w * p.value;
                    }
                    s += w;
                    if r > 0.0 {
                        // ∇W = dW/dr · (x − x_j)/r
                        let g = (x - p.pos) * (p.weight_scale * df * p.inv_h / r);
                        if !UNIT {
                            ga += g * p.value;
                        }
                        gs += g;
                    }
                }
            }
        }
        if UNIT {
            (a, ga) = (s, gs);
        }
        if self.shepard {
            if s > 0.0 {
                let v = a / s;
                ga = (ga - gs * v) / s;
                a = v;
            } else {
                a = 0.0;
                ga = DVec3::ZERO;
            }
        }
        Sample {
            value: a,
            gradient: ga,
            weight: s,
            weight_gradient: gs,
        }
    }

    /// SPH interpolation of several per-particle arrays (grid order, `components` each),
    /// normalised by the sum of weights (Shepard), as surface attributes should be.
    pub fn interpolate(&self, x: DVec3, arrays: &[(&[f64], usize)], out: &mut [f64]) {
        out.iter_mut().for_each(|v| *v = 0.0);
        let mut s = 0.0;
        self.for_each_neighbour(x, |slot, p, r2| {
            let w = p.weight_scale * self.kernel.shape(r2.sqrt() * p.inv_h).0;
            s += w;
            let mut o = 0;
            for (data, c) in arrays {
                for k in 0..*c {
                    out[o + k] += w * data[slot * c + k];
                }
                o += c;
            }
        });
        if s > 0.0 {
            out.iter_mut().for_each(|v| *v /= s);
        }
    }

    /// Reorders an original-order array with `components` per particle into grid order,
    /// for [`SphField::interpolate`].
    pub fn to_grid_order(&self, data: &[f64], components: usize) -> Vec<f64> {
        self.grid
            .order()
            .iter()
            .flat_map(|&i| {
                data[i as usize * components..(i as usize + 1) * components]
                    .iter()
                    .copied()
            })
            .collect()
    }

    /// Number of particles.
    pub fn len(&self) -> usize {
        self.particles.len()
    }

    /// True when the field has no particle (never, once built).
    pub fn is_empty(&self) -> bool {
        self.particles.is_empty()
    }

    /// Position of the particle in grid slot `slot`.
    pub fn position(&self, slot: usize) -> DVec3 {
        self.particles[slot].pos
    }

    /// The raw (unsmoothed) value A_j of the particle in grid slot `slot`.
    pub fn raw_value(&self, slot: usize) -> f64 {
        self.particles[slot].value
    }

    /// Smoothing length before scaling of the particle in `slot`.
    pub fn h_unscaled(&self, slot: usize) -> f64 {
        self.h_unscaled[slot]
    }

    /// Kernel support radius (after scaling) of the particle in `slot`.
    pub fn support(&self, slot: usize) -> f64 {
        self.particles[slot].support2.sqrt()
    }

    /// The smallest unscaled smoothing length (sizes the virtual grid).
    pub fn min_h(&self) -> f64 {
        self.h_unscaled.iter().fold(f64::INFINITY, |m, &v| m.min(v))
    }

    /// The largest unscaled smoothing length.
    pub fn max_h(&self) -> f64 {
        self.h_unscaled.iter().fold(0.0, |m, &v| m.max(v))
    }

    /// The largest support radius after scaling.
    pub fn max_support(&self) -> f64 {
        self.max_support
    }

    /// The h-scale factor the field was built with.
    pub fn h_scale(&self) -> f64 {
        self.h_scale
    }

    /// The kernel.
    pub fn kernel(&self) -> Kernel {
        self.kernel
    }

    /// Whether values are Shepard-normalised.
    pub fn shepard(&self) -> bool {
        self.shepard
    }

    /// Whether the value is the sum of weights itself, to the bit, at every point: unit
    /// values without Shepard normalisation (the free surface's field, A = S).
    pub fn value_is_weight(&self) -> bool {
        self.unit_values && !self.shepard
    }

    /// The particle in grid slot `slot` as the evaluation loop uses it: (position,
    /// support², 1/h, V σ / h³, A). GPU kernels repeat that loop on these numbers.
    pub fn packed(&self, slot: usize) -> (DVec3, f64, f64, f64, f64) {
        let p = &self.particles[slot];
        (p.pos, p.support2, p.inv_h, p.weight_scale, p.value)
    }

    /// The neighbour grid the evaluation loop searches (slots are grid order).
    pub fn neighbour_grid(&self) -> &NeighbourGrid {
        &self.grid
    }

    /// Neighbour-grid cells searched on each side of a query point.
    pub fn search_reach(&self) -> u32 {
        REACH as u32
    }
}

/// A warning when the kernel's support is wider than the whole particle set: every
/// particle is then a neighbour of every other (N² pairs: minutes on large frames, and a
/// surface smoothed into a blob). Usually h was given in other units than the positions.
fn support_spans_the_data(
    n: usize,
    support: f64,
    (lo, hi): (DVec3, DVec3),
    settings: &SphSettings,
) -> Option<String> {
    // A few particles under one wide kernel can be meant; hundreds are a frame.
    let extent = (hi - lo).length();
    (n >= 100 && support > extent).then(|| {
        let h = support / (settings.kernel.support_factor() * settings.h_scale);
        format!(
            "the kernel support ({support:.4}, from h = {h}) is wider than the particles' \
             extent ({extent:.4}): every particle neighbours every other, which is slow and \
             smooths the surface away; are h and the positions in the same units?"
        )
    })
}

impl ScalarField for SphField {
    fn value(&self, x: DVec3) -> f64 {
        self.value_and_weight(x).0
    }
    fn value_and_gradient(&self, x: DVec3) -> (f64, DVec3) {
        let s = self.sample(x);
        (s.value, s.gradient)
    }
    fn values_on_tile(
        &self,
        origin: DVec3,
        spacing: f64,
        first: [i64; 3],
        rows: &[u8; TILE * TILE],
        out: &mut [f64; TILE * TILE * TILE],
    ) {
        self.values_on_lattice_tile(origin, spacing, first, rows, out);
    }
}

fn scalar_array(data: &ParticleData, name: &str, role: &str) -> Result<Vec<f64>> {
    let a = data.require(name)?;
    if a.components != 1 {
        return Err(Error::InvalidInput(format!(
            "{role} array '{name}' has {} components, expected 1",
            a.components
        )));
    }
    Ok(a.data.clone())
}

fn masses(data: &ParticleData, spec: &Mass) -> Result<Vec<f64>> {
    let m = match spec {
        Mass::Constant(m) => vec![*m; data.len()],
        Mass::Array(name) => scalar_array(data, name, "mass")?,
    };
    check_positive(&m, "mass")?;
    Ok(m)
}

fn check_positive(v: &[f64], role: &str) -> Result<()> {
    match v.iter().position(|x| !(*x > 0.0 && x.is_finite())) {
        None => Ok(()),
        Some(i) => Err(Error::InvalidInput(format!(
            "{role} of particle {i} is {}; it must be positive and finite",
            v[i]
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::field::particles::Attribute;

    /// A jittered block of particles and points around and inside it.
    fn block() -> (ParticleData, Vec<DVec3>) {
        let mut next = crate::test_rng::unit(11);
        let mut positions = Vec::new();
        for i in 0..10 {
            for j in 0..10 {
                for k in 0..10 {
                    let jitter = DVec3::new(next(), next(), next()) * 0.3;
                    positions.push(DVec3::new(i as f64, j as f64, k as f64) * 0.1 + jitter * 0.1);
                }
            }
        }
        let points = (0..300)
            .map(|_| DVec3::new(next(), next(), next()) * 1.3 - DVec3::splat(0.15))
            .collect();
        let data = ParticleData {
            positions,
            attributes: vec![],
            ..Default::default()
        };
        (data, points)
    }

    #[test]
    fn the_unit_value_loops_equal_the_general_loops_to_the_bit() {
        let (data, points) = block();
        for kernel in [
            Kernel::CubicSpline,
            Kernel::WendlandC2,
            Kernel::QuinticSpline,
            Kernel::Quadratic,
        ] {
            {
                let settings = SphSettings {
                    kernel,
                    smoothing_length: SmoothingLength::Constant(0.11),
                    quantity: Quantity::SumOfWeights,
                    ..SphSettings::default()
                };
                let field = SphField::new(&data, &settings).unwrap();
                assert!(field.unit_values, "the sum of weights has unit values");
                let mut inside = 0;
                for &x in &points {
                    let (a, s) =
                        with_kernel!(kernel, K => field.value_and_weight_with::<false>(K, x));
                    assert_eq!(field.value_and_weight(x), (a, s), "{kernel:?} at {x}");
                    let general = with_kernel!(kernel, K => field.sample_with::<false>(K, x));
                    assert_eq!(field.sample(x), general, "{kernel:?} at {x}");
                    inside += usize::from(s > 0.0);
                }
                assert!(inside > 200, "most points see particles ({inside})");
            }
        }
    }

    /// Shepard normalisation of the sum of weights is 1 wherever a particle reaches: no
    /// surface at any isovalue, so it is refused up front rather than reported as an
    /// empty surface blamed on the grid. A field array that varies is Shepard's use.
    #[test]
    fn shepard_of_the_sum_of_weights_is_refused() {
        let (mut data, _) = block();
        let n = data.positions.len();
        data.attributes.push(Attribute::scalar("one", vec![1.0; n]));
        data.attributes
            .push(Attribute::scalar("p", (0..n).map(|i| i as f64).collect()));
        for (quantity, refused) in [
            (Quantity::SumOfWeights, true),
            // Data, not a setting: accepted (a piece of a larger set may be all 1).
            (Quantity::Scalar("one".into()), false),
            (Quantity::Scalar("p".into()), false),
        ] {
            let settings = SphSettings {
                smoothing_length: SmoothingLength::Constant(0.11),
                quantity: quantity.clone(),
                shepard: true,
                ..SphSettings::default()
            };
            match SphField::new(&data, &settings) {
                Err(e) => {
                    assert!(refused, "{quantity:?}: {e}");
                    assert!(e.to_string().contains("turn Shepard off"), "{e}");
                }
                Ok(_) => assert!(!refused, "{quantity:?} accepted"),
            }
        }
    }

    /// Rows of nodes (lanes) give each node's sums to the bit, for every kernel, with
    /// smoothing lengths varying by 1.75×, signed values, with and without Shepard,
    /// inside the block, across its faces and outside it.
    #[test]
    fn rows_of_nodes_equal_node_by_node_to_the_bit() {
        let (mut data, points) = block();
        let n = data.positions.len();
        let mut next = crate::test_rng::unit(5);
        let h = (0..n).map(|_| 0.08 + 0.06 * next()).collect();
        let p = (0..n).map(|_| next() - 0.3).collect();
        data.attributes.push(Attribute::scalar("h", h));
        data.attributes.push(Attribute::scalar("p", p));
        for kernel in Kernel::ALL {
            for quantity in [Quantity::SumOfWeights, Quantity::Scalar("p".into())] {
                // Shepard of the sum of weights is refused (constant 1).
                let sheparded: &[bool] = match quantity {
                    Quantity::SumOfWeights => &[false],
                    _ => &[false, true],
                };
                for &shepard in sheparded {
                    let settings = SphSettings {
                        kernel,
                        smoothing_length: SmoothingLength::Array("h".into()),
                        quantity: quantity.clone(),
                        shepard,
                        ..SphSettings::default()
                    };
                    let field = SphField::new(&data, &settings).unwrap();
                    let (mut reached, mut lanes) = (0, 0);
                    for &x in &points {
                        let xs = std::array::from_fn(|l| x.x + 0.029 * l as f64);
                        let row = field.values_on_row(xs, x.y, x.z);
                        for (l, &(a, s)) in row.iter().enumerate() {
                            let (va, vs) = field.value_and_weight(DVec3::new(xs[l], x.y, x.z));
                            assert_eq!(
                                (a.to_bits(), s.to_bits()),
                                (va.to_bits(), vs.to_bits()),
                                "{kernel:?} {quantity:?} shepard {shepard}: lane {l} of {x}"
                            );
                            reached += usize::from(s > 0.0);
                            lanes += 1;
                        }
                    }
                    assert!(
                        reached > lanes / 2 && reached < lanes,
                        "{reached} of {lanes}"
                    );
                }
            }
        }
    }

    /// The value is the weight for the sum of weights and for an array of ones without
    /// Shepard; not with Shepard (1 where a particle reaches), nor for other values.
    #[test]
    fn the_value_is_the_weight_only_for_unit_values_without_shepard() {
        let (mut data, points) = block();
        let n = data.positions.len();
        data.attributes.push(Attribute::scalar("one", vec![1.0; n]));
        data.attributes.push(Attribute::scalar(
            "p",
            (0..n).map(|i| 1.0 + i as f64).collect(),
        ));
        for (quantity, shepard, expected) in [
            (Quantity::SumOfWeights, false, true),
            (Quantity::Scalar("one".into()), false, true),
            (Quantity::Scalar("one".into()), true, false),
            (Quantity::Scalar("p".into()), false, false),
        ] {
            let settings = SphSettings {
                smoothing_length: SmoothingLength::Constant(0.11),
                quantity: quantity.clone(),
                shepard,
                ..SphSettings::default()
            };
            let field = SphField::new(&data, &settings).unwrap();
            assert_eq!(
                field.value_is_weight(),
                expected,
                "{quantity:?} shepard {shepard}"
            );
            let mut differ = 0;
            for &x in &points {
                let (a, s) = field.value_and_weight(x);
                if expected {
                    assert_eq!(a.to_bits(), s.to_bits(), "{quantity:?} at {x}");
                }
                differ += usize::from(a != s);
            }
            assert_eq!(
                differ == 0,
                expected,
                "{quantity:?} shepard {shepard}: {differ}"
            );
        }
    }

    #[test]
    fn a_field_with_other_values_takes_the_general_loops() {
        let (mut data, _) = block();
        let n = data.positions.len();
        let values: Vec<f64> = (0..n).map(|i| if i == 7 { 2.0 } else { 1.0 }).collect();
        data.attributes.push(Attribute::scalar("p", values));
        let settings = SphSettings {
            smoothing_length: SmoothingLength::Constant(0.11),
            quantity: Quantity::Scalar("p".into()),
            ..SphSettings::default()
        };
        let field = SphField::new(&data, &settings).unwrap();
        assert!(!field.unit_values);
        let x = data.positions[7];
        let (a, s) = field.value_and_weight(x);
        assert!(a > s, "particle 7's value 2 shows in A(x): {a} vs S(x) {s}");
    }
}
