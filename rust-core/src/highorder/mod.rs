//! Isosurfaces of high-order finite elements sampled by a particle system (Meyer, Nelson,
//! Kirby, Whitaker 2007; `../shared/papers/particle-systems-high-order-fe-isosurfaces.txt`).
//!
//! Particles live in reference space (a cell and reference coordinates), so the basis is
//! always evaluated in closed form and no world point is ever inverted except when a
//! particle crosses a face. They are projected onto F = C by Newton steps (eq. 1) to ε_T,
//! repel each other with the compact cotangent energy over curvature-scaled world
//! distances (eqs. 2–6), move along world velocities mapped to reference space by K
//! (eq. 21) and projected on the tangent plane (eq. 4), with per-particle adaptive steps
//! and the paper's accept/reject rules. Updates are Jacobi sweeps (every particle moves
//! against the previous sweep's positions) so they run in parallel and give the same
//! result for any thread count. Coarse-to-fine levels, then split/delete against the
//! ideal hexagonal energy with a seeded random bias, until the count settles.

pub mod cli;
mod energy;
pub mod marching;
mod neighbours;
mod particle;
mod seed;
mod splats;
mod system;
#[cfg(test)]
pub(crate) mod tests;

use energy::BETA;
pub use energy::{alpha, energy, energy_derivative, ideal_energy};

use crate::error::{Error, Result};
use crate::field::fe::{FeMesh, Scratch};
use crate::field::particles::Attribute;
use crate::field::sph::Quantity;
use crate::progress::Progress;
use crate::samples::PointSamples;
use particle::Surface;
use rayon::prelude::*;
use std::borrow::Cow;
use std::sync::atomic::AtomicU64;

/// Parameters of [`sample`].
#[derive(Clone, Debug)]
pub struct Params {
    /// The isovalue C.
    pub iso: f64,
    /// s: particle spacing on a flat surface, world units; 0 picks 1/40 of the mesh's
    /// bounding-box diagonal.
    pub spacing: f64,
    /// ρ: extra density per unit angle on curved surfaces (0: uniform spacing).
    pub rho: f64,
    /// ε_T: every sample has |F − C| ≤ tolerance.
    pub tolerance: f64,
    /// Upper bound on the curvature scaling of α, as a multiple of the flat value
    /// (bounds the density near singular points).
    pub max_density: f64,
    /// Coarse-to-fine levels above the final spacing (each halves s): at least this many,
    /// more while the seeds lie sparser than the coarsest spacing.
    pub levels: usize,
    /// Most sweeps per relaxation.
    pub max_iterations: usize,
    /// Steady state: relative change of the system energy below this (paper: 0.15 %).
    pub steady_fraction: f64,
    /// Neighbour lists are rebuilt every this many sweeps (paper: 5).
    pub neighbour_refresh: usize,
    /// Most split/delete rounds at the final spacing.
    pub split_rounds: usize,
    /// Seed of the random bias in split/delete decisions.
    pub seed: u64,
}

impl Default for Params {
    fn default() -> Self {
        Params {
            iso: 0.0,
            spacing: 0.0,
            rho: 0.0,
            tolerance: 1e-6,
            max_density: 8.0,
            levels: 2,
            max_iterations: 60,
            steady_fraction: 0.0015,
            neighbour_refresh: 5,
            split_rounds: 6,
            seed: 1,
        }
    }
}

/// What a run did.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Stats {
    /// Particles returned.
    pub particles: usize,
    /// Projected seeds before thinning.
    pub seeds: usize,
    /// Relaxation sweeps over all levels.
    pub iterations: usize,
    /// Forward evaluations (basis functions, mapping and field at one reference point).
    pub evaluations: u64,
    /// Particles added by splitting (not counting coarse-to-fine refinement).
    pub splits: usize,
    /// Particles deleted.
    pub deletes: usize,
    /// The spacing s used.
    pub spacing: f64,
    /// Largest |F − C| over the returned samples.
    pub max_residual: f64,
    /// What the caller should tell the user although nothing failed: an isovalue that
    /// gave no sample (see [`crate::correctors::Stats::warnings`]).
    pub warnings: Vec<String>,
}

/// Samples the isosurface `params.iso` of the point array `field` of `mesh` with the
/// particle system. Returns oriented points with radius and the arrays "Element",
/// "Reference" (3), "Curvature" (D = sqrt(κ1² + κ2²)) and "Energy".
pub fn sample(
    mesh: &FeMesh,
    field: &str,
    params: &Params,
    progress: &mut Progress,
) -> Result<(PointSamples, Stats)> {
    check(params)?;
    let values = field_array(mesh, field)?;
    // Counted over the caller's points that cells use: the points made for serendipity
    // cells inherit their NaNs, and a point no volume cell uses bears on no cell.
    let used = mesh.used_points();
    let given = &values[..mesh.given_points()];
    let gap = |i: usize| used[i] && !given[i].is_finite();
    let gaps = (0..given.len()).filter(|&i| gap(i)).count();
    let spacing = if params.spacing > 0.0 {
        params.spacing
    } else {
        let (lo, hi) = mesh.bounds();
        (hi - lo).length() / 40.0
    };
    let surface = Surface {
        mesh,
        values: &values,
        iso: params.iso,
        tolerance: params.tolerance,
        curvature_in_projection: params.rho > 0.0,
        evaluations: AtomicU64::new(0),
        gaps: gaps > 0,
    };
    let (mut particles, mut stats) = system::run(&surface, params, spacing, progress)?;
    if gaps > 0 {
        let first = (0..given.len()).find(|&i| gap(i)).unwrap_or(0);
        stats.warnings.insert(
            0,
            format!(
                "field '{field}' has {gaps} non-finite {} (the first at point {first}): the \
                 cells that touch one are left out",
                if gaps == 1 { "value" } else { "values" }
            ),
        );
    }
    if let Some(w) = mesh.left_out_warning() {
        stats.warnings.insert(0, w);
    }
    if !surface.curvature_in_projection {
        particles
            .par_iter_mut()
            .for_each_init(Scratch::default, |sc, p| {
                p.d = surface.curvature(p, sc);
            });
    }
    stats.spacing = spacing;
    stats.particles = particles.len();
    stats.evaluations = surface.evaluations.into_inner();
    stats.max_residual = particles.iter().map(|p| p.residual).fold(0.0, f64::max);
    Ok((to_samples(mesh, &particles, params, spacing), stats))
}

fn check(p: &Params) -> Result<()> {
    let bad = |name, message: &str| {
        Err(Error::InvalidParameter {
            name,
            message: message.into(),
        })
    };
    if !p.iso.is_finite() {
        return bad("iso", "must be finite");
    }
    if !(p.tolerance > 0.0 && p.tolerance.is_finite()) {
        return bad("tolerance", "must be positive");
    }
    if !(p.spacing >= 0.0 && p.spacing.is_finite()) {
        return bad(
            "spacing",
            "must be ≥ 0 (0 picks 1/40 of the mesh's diagonal)",
        );
    }
    if !(p.rho >= 0.0 && p.rho.is_finite()) {
        return bad("rho", "must be ≥ 0");
    }
    if !(p.max_density >= 1.0 && p.max_density.is_finite()) {
        return bad("max_density", "must be ≥ 1");
    }
    if p.levels > 8 {
        return bad("levels", "at most 8 (each level halves the spacing)");
    }
    if p.neighbour_refresh == 0 {
        return bad("neighbour_refresh", "must be ≥ 1");
    }
    Ok(())
}

/// The field named `name`: a scalar point array, or "NAME:K", component K (from 0) of a
/// point array with several components, parsed as `isobar sph --field` parses it
/// ([`Quantity::parse`]); an array whose whole name is `name` wins. A magnitude
/// ("NAME:mag") is refused: |v| of the element's vector polynomial is not a polynomial of
/// the element, and interpolating the nodes' magnitudes would be another field. Every
/// value must be finite (see [`field_array`] for a field with gaps).
pub(crate) fn field_values<'m>(mesh: &'m FeMesh, name: &str) -> Result<Cow<'m, [f64]>> {
    let values = field_array(mesh, name)?;
    if let Some(i) = values.iter().position(|v| !v.is_finite()) {
        return Err(Error::InvalidInput(format!(
            "{}: field '{name}' has a non-finite value at point {i}",
            mesh.name()
        )));
    }
    Ok(values)
}

/// [`field_values`], non-finite values allowed: solvers write NaN where a region is
/// masked, and the sampler leaves out the cells that touch one.
pub(crate) fn field_array<'m>(mesh: &'m FeMesh, name: &str) -> Result<Cow<'m, [f64]>> {
    let missing = |wanted: &str| {
        let available = mesh
            .point_data
            .iter()
            .map(|a| match a.components {
                1 => a.name.clone(),
                c => format!("{} ({c} components)", a.name),
            })
            .collect::<Vec<_>>();
        Error::InvalidInput(format!(
            "{}: no point array named '{wanted}' in the finite elements (point arrays: {})",
            mesh.name(),
            if available.is_empty() {
                "none".to_string()
            } else {
                available.join(", ")
            }
        ))
    };
    let find = |wanted: &str| mesh.point_data.iter().find(|a| a.name == wanted);
    let (a, component) = match find(name) {
        Some(a) => (a, None),
        None => match Quantity::parse(name) {
            Quantity::Component(array, k) => (find(&array).ok_or_else(|| missing(&array))?, Some(k)),
            Quantity::Magnitude(array) if find(&array).is_some() => {
                return Err(Error::InvalidInput(format!(
                    "{}: field '{name}': the magnitude of a vector array is not a finite-element field; choose a component '{array}:K'",
                    mesh.name()
                )))
            }
            _ => return Err(missing(name)),
        },
    };
    let values: Cow<'m, [f64]> = match component {
        None if a.components == 1 => Cow::Borrowed(&a.data),
        None => {
            return Err(Error::InvalidInput(format!(
                "{}: point array '{name}' has {} components; the field must be a scalar array or a component '{name}:K'",
                mesh.name(),
                a.components
            )))
        }
        Some(k) if k >= a.components => {
            return Err(Error::InvalidInput(format!(
                "{}: field '{name}': point array '{}' has {} components, component {k} does not exist",
                mesh.name(),
                a.name,
                a.components
            )))
        }
        Some(k) => a.data.iter().skip(k).step_by(a.components).copied().collect(),
    };
    Ok(values)
}

fn to_samples(
    mesh: &FeMesh,
    particles: &[particle::Particle],
    params: &Params,
    s: f64,
) -> PointSamples {
    let amax = params.max_density * BETA / s;
    let mut out = PointSamples::default();
    let mut element = Vec::with_capacity(particles.len());
    let mut reference = Vec::with_capacity(3 * particles.len());
    let mut curvature = Vec::with_capacity(particles.len());
    let mut energy = Vec::with_capacity(particles.len());
    // Local spacing d = β/α; a hexagonal Voronoi cell of spacing d fits in a disk of
    // radius d/√3 = β d. The packing is not even: each radius reaches its own cell.
    let even: Vec<f64> = particles
        .iter()
        .map(|p| BETA * BETA / alpha(s, params.rho, p.d, amax))
        .collect();
    out.radii = splats::covering_radii(particles, &even);
    for p in particles {
        out.positions.push(p.x.to_array());
        out.normals.push(p.n.as_vec3().to_array());
        element.push(mesh.given_cell(p.cell as usize) as f64);
        reference.extend(mesh.given_reference(p.cell as usize, p.u).to_array());
        curvature.push(p.d);
        energy.push(p.energy);
    }
    let attr = |name: &str, components, data| Attribute {
        name: name.into(),
        components,
        data,
    };
    out.attributes = vec![
        attr("Element", 1, element),
        attr("Reference", 3, reference),
        attr("Curvature", 1, curvature),
        attr("Energy", 1, energy),
    ];
    out
}
