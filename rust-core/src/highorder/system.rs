//! The distribution loop: relaxation sweeps to a steady state, split/delete rounds and
//! coarse-to-fine levels (the paper's §4 steps 1–4 and §4.1).

use super::energy::{alpha, energy, energy_derivative, ideal_energy, BETA};
use super::neighbours::Neighbours;
use super::particle::{Particle, Surface};
use super::{seed, Params, Stats};
use crate::error::Result;
use crate::field::fe::Scratch;
use crate::progress::Progress;
use glam::DVec3;
use rayon::prelude::*;
use rustc_hash::FxHashSet;

/// Per-level constants.
struct Level {
    s: f64,
    rho: f64,
    alpha_max: f64,
}

impl Level {
    fn new(s: f64, params: &Params) -> Level {
        Level {
            s,
            rho: params.rho,
            alpha_max: params.max_density * BETA / s,
        }
    }

    /// Largest world distance at which two particles interact (α at its flat minimum).
    fn reach(&self) -> f64 {
        self.s / BETA
    }

    /// Local target spacing at curvature magnitude d.
    fn spacing_at(&self, d: f64) -> f64 {
        BETA / alpha(self.s, self.rho, d, self.alpha_max)
    }

    /// Energy and repulsive velocity (eqs. 2–3 with eq. 5's scaled distances) of a particle
    /// at `x` with normal `n` and curvature `d` among `others`.
    fn energy_and_velocity(
        &self,
        x: DVec3,
        n: DVec3,
        d: f64,
        others: &[u32],
        all: &[Particle],
    ) -> (f64, DVec3) {
        let mut e = 0.0;
        let mut v = DVec3::ZERO;
        for &j in others {
            let q = &all[j as usize];
            if n.dot(q.n) <= 0.0 {
                continue;
            }
            let dv = x - q.x;
            let dist = dv.length();
            let a = alpha(self.s, self.rho, 0.5 * (d + q.d), self.alpha_max);
            let r = a * dist;
            if r >= 1.0 || dist == 0.0 {
                continue;
            }
            e += energy(r);
            v -= dv * (energy_derivative(r) * a / dist);
        }
        (e, v)
    }
}

/// Seeds, then every level from coarse to fine; returns the final particles.
pub(crate) fn run(
    surface: &Surface,
    params: &Params,
    spacing: f64,
    progress: &mut Progress,
) -> Result<(Vec<Particle>, Stats)> {
    let mut stats = Stats::default();
    progress.phase("seeding", 0.0, 0.1)?;
    let lambda0 = 0.1 * spacing * spacing;
    let seed::Seeds {
        particles: seeds,
        cells,
        extent,
    } = seed::seeds(surface, lambda0);
    stats.seeds = seeds.len();
    if seeds.is_empty() {
        stats.warnings.push(if cells == 0 && surface.gaps {
            format!(
                "no surface at isovalue {}: the field never crosses it where it is finite",
                surface.iso
            )
        } else if cells == 0 {
            crate::mesh::no_surface(surface.iso)
        } else {
            format!(
                "no sample at isovalue {}: the field may cross it in {cells} {}, but no \
                 projection onto it reached the tolerance {:e}",
                surface.iso,
                if cells == 1 { "cell" } else { "cells" },
                surface.tolerance
            )
        });
        return Ok((seeds, stats));
    }
    let top = coarsest_level(params.levels, spacing, extent, seeds.len());
    let mut particles = thin(seeds, spacing * 2f64.powi(top as i32));
    let mut sc = Scratch::default();
    for level in (0..=top).rev() {
        let lv = Level::new(spacing * 2f64.powi(level as i32), params);
        let (from, to) = (
            0.1 + 0.9 * (top - level) as f64 / (top + 1) as f64,
            0.1 + 0.9 * (top - level + 1) as f64 / (top + 1) as f64,
        );
        progress.phase("distributing", from, to)?;
        let rounds = if level == 0 { params.split_rounds } else { 2 };
        relax(surface, &lv, params, &mut particles, &mut stats, progress)?;
        for round in 0..rounds {
            let before = particles.len();
            let (split, deleted) = split_delete(
                surface,
                &lv,
                params,
                &mut particles,
                (level * 64 + round) as u64,
                &mut sc,
            );
            stats.splits += split;
            stats.deletes += deleted;
            progress.report((round + 1) as f64 / (rounds + 1) as f64)?;
            if split + deleted == 0 {
                break;
            }
            relax(surface, &lv, params, &mut particles, &mut stats, progress)?;
            // Settled: fewer than 0.5 % of the particles changed.
            if (split + deleted) * 200 < before {
                break;
            }
        }
        if level > 0 {
            check_population(particles.len(), level, spacing)?;
            particles = refine(surface, &lv, params, &particles, level as u64);
        }
    }
    Ok((particles, stats))
}

/// Most samples a run may make: a spacing far below the surface's scale would otherwise run
/// for hours and fill memory (about 200 bytes a particle with its neighbour lists).
const MAX_SAMPLES: usize = 1 << 24;

/// The coarsest level: at least `levels` above the final spacing, more while the seeds are
/// sparser than that level's spacing, and no coarser than a quarter of the
/// extent. The seeds are a few per cut cell whatever the spacing, and splitting grows the
/// population about one spacing a round, so from seeds far apart at a fine coarsest level
/// it never covers the surface (a plane through one cell at s = 1/100 of it was sampled in
/// patches around its 16 seeds). `gap` guesses the seeds' distance as if they were spread
/// evenly over a square of the extent's side. The extent is that of the box of the cells the
/// field may cross, not of the seeds (a cap through one face of one cell was seeded at one
/// end only); it can exceed the surface's (a small sphere inside one large cell), which
/// only starts the run a level coarser.
fn coarsest_level(levels: usize, spacing: f64, extent: f64, seeds: usize) -> usize {
    let gap = extent / (seeds as f64).sqrt();
    let at = |level: usize| spacing * 2f64.powi(level as i32);
    let mut top = 0;
    while at(top + 1) <= extent / 4.0 && (top < levels || at(top) < gap) {
        top += 1;
    }
    top
}

/// Refuses a run whose final spacing needs more than [`MAX_SAMPLES`]: `count` particles
/// settled at `level` above it become about `count · 4^level` at the final spacing.
fn check_population(count: usize, level: usize, spacing: f64) -> Result<()> {
    let expected = count as f64 * 4f64.powi(level as i32);
    if expected <= MAX_SAMPLES as f64 {
        return Ok(());
    }
    Err(crate::error::Error::InvalidParameter {
        name: "spacing",
        message: format!(
            "{spacing} would need about {expected:.2e} samples on this surface, over the \
             {MAX_SAMPLES} the particle system takes; choose a spacing of at least {:.3e}",
            spacing * (expected / MAX_SAMPLES as f64).sqrt()
        ),
    })
}

/// Keeps the first particle of each bin of size `h`, in order.
fn thin(particles: Vec<Particle>, h: f64) -> Vec<Particle> {
    let mut seen = FxHashSet::default();
    particles
        .into_iter()
        .filter(|p| seen.insert((p.x / h).floor().as_i64vec3().to_array()))
        .collect()
}

/// Jacobi sweeps until the system energy changes by less than `steady_fraction`.
fn relax(
    surface: &Surface,
    lv: &Level,
    params: &Params,
    particles: &mut Vec<Particle>,
    stats: &mut Stats,
    progress: &mut Progress,
) -> Result<()> {
    let mut neighbours = Neighbours::build(particles, lv.reach() * 1.25);
    let mut previous = f64::NAN;
    for it in 0..params.max_iterations {
        if it > 0 && it % params.neighbour_refresh == 0 {
            neighbours = Neighbours::build(particles, lv.reach() * 1.25);
        }
        let snapshot: &[Particle] = particles;
        let next: Vec<Particle> = (0..snapshot.len())
            .into_par_iter()
            .map_init(Scratch::default, |sc, i| {
                step(surface, lv, snapshot, neighbours.of(i), i, sc)
            })
            .collect();
        *particles = next;
        stats.iterations += 1;
        progress.report(0.0)?;
        let total: f64 = particles.iter().map(|p| p.energy).sum();
        if (total - previous).abs() <= params.steady_fraction * total {
            break;
        }
        previous = total;
    }
    Ok(())
}

/// One particle's update (the paper's step 1): tangent move scaled by λ, reprojection,
/// accepted if it lowers the energy, stays on the surface and within the mesh, and moves
/// no further than s; otherwise λ shrinks tenfold and it tries again.
fn step(
    surface: &Surface,
    lv: &Level,
    all: &[Particle],
    others: &[u32],
    i: usize,
    sc: &mut Scratch,
) -> Particle {
    let p = all[i];
    let (e, v) = lv.energy_and_velocity(p.x, p.n, p.d, others, all);
    let vt = v - p.n * p.n.dot(v);
    let mut lambda = p.lambda;
    if vt.length_squared() == 0.0 {
        return Particle { energy: e, ..p };
    }
    for attempt in 0..6 {
        let dx = vt * lambda;
        if dx.length() <= lv.s {
            if let Some(q) = surface.moved(&p, dx, sc) {
                if q.x.distance(p.x) <= lv.s {
                    let (eq, _) = lv.energy_and_velocity(q.x, q.n, q.d, others, all);
                    if eq <= e {
                        let grow = if attempt == 0 { 10.0 } else { 1.0 };
                        return Particle {
                            lambda: lambda * grow,
                            energy: eq,
                            ..q
                        };
                    }
                }
            }
        }
        lambda *= 0.1;
    }
    Particle {
        lambda,
        energy: e,
        ..p
    }
}

/// Deterministic uniform number in [0, 1) for (seed, round, index).
fn random(seed: u64, round: u64, i: u64) -> f64 {
    let mut z =
        seed ^ round.wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ i.wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 30)).wrapping_mul(0xbf58_476d_1ce4_e5b9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94d0_49bb_1331_11eb);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 53) as f64
}

/// A tangent unit vector at a random angle around `n`.
fn tangent(n: DVec3, angle: f64) -> DVec3 {
    let t1 = n.any_orthonormal_vector();
    let t2 = n.cross(t1);
    t1 * angle.cos() + t2 * angle.sin()
}

/// The paper's step 3: energies biased by a random factor in [0.75, 1.25) split below
/// 0.35 E_ideal (a new particle half a spacing away) and die above 1.75 E_ideal. Only a
/// particle whose biased energy is the highest among its neighbours dies, so a crowded
/// patch thins out instead of vanishing at once.
fn split_delete(
    surface: &Surface,
    lv: &Level,
    params: &Params,
    particles: &mut Vec<Particle>,
    round: u64,
    sc: &mut Scratch,
) -> (usize, usize) {
    let ideal = ideal_energy();
    let biased: Vec<f64> = particles
        .iter()
        .enumerate()
        .map(|(i, p)| p.energy * (0.75 + 0.5 * random(params.seed, round, i as u64)))
        .collect();
    let neighbours = Neighbours::build(particles, lv.reach());
    let mut out = Vec::with_capacity(particles.len());
    let mut added = Vec::new();
    let (mut split, mut deleted) = (0, 0);
    for (i, p) in particles.iter().enumerate() {
        let b = biased[i];
        let highest = neighbours
            .of(i)
            .iter()
            .all(|&j| (biased[j as usize], j as usize) < (b, i));
        if b > 1.75 * ideal && highest {
            deleted += 1;
            continue;
        }
        out.push(*p);
        if b < 0.35 * ideal {
            let angle = std::f64::consts::TAU * random(params.seed ^ 0x5eed, round, i as u64);
            let dx = tangent(p.n, angle) * (0.5 * lv.spacing_at(p.d));
            if let Some(q) = surface.moved(p, dx, sc) {
                added.push(q);
                split += 1;
            }
        }
    }
    out.extend(added);
    *particles = out;
    (split, deleted)
}

/// Coarse-to-fine: each particle becomes four (itself and three at 120° around it, one
/// finer spacing away).
fn refine(
    surface: &Surface,
    lv: &Level,
    params: &Params,
    particles: &[Particle],
    level: u64,
) -> Vec<Particle> {
    let finer = Level::new(lv.s * 0.5, params);
    let added: Vec<Vec<Particle>> = particles
        .par_iter()
        .enumerate()
        .map_init(Scratch::default, |sc, (i, p)| {
            let base = std::f64::consts::TAU * random(params.seed ^ 0xf1e, level, i as u64);
            let d = finer.spacing_at(p.d);
            let lambda = 0.1 * finer.s * finer.s;
            let mut out = vec![Particle { lambda, ..*p }];
            for k in 0..3 {
                let dx = tangent(p.n, base + k as f64 * std::f64::consts::TAU / 3.0) * d;
                if let Some(q) = surface.moved(p, dx, sc) {
                    out.push(Particle { lambda, ..q });
                }
            }
            out
        })
        .collect();
    added.into_iter().flatten().collect()
}
