//! Particle arrays carried onto a surface: each vertex takes the SPH interpolation of the
//! arrays, normalised by the sum of weights (Shepard), so a constant array stays constant
//! up to the free surface. Every extractor that meshes an SPH field carries arrays this
//! one way: Marching Correctors, its full-grid baseline and the adaptive 3-level grids.

use super::SphField;
use crate::error::{Error, Result};
use crate::field::particles::{Attribute, ParticleData};
use crate::progress::{chunked, Progress};
use glam::DVec3;
use rayon::prelude::*;

/// Surface arrays the extractors write themselves.
pub const RESERVED: [&str; 2] = ["SumOfWeights", "Isovalue"];

/// Particle arrays to carry onto a surface, reordered as the field's neighbour search
/// visits the particles.
pub struct Carried {
    arrays: Vec<(String, usize, Vec<f64>)>,
}

impl Carried {
    /// Looks up `names` in `data`; a missing name is an error that lists what exists.
    /// Checked before an extraction starts, so a typo costs no surface.
    pub fn new(field: &SphField, data: &ParticleData, names: &[String]) -> Result<Self> {
        let mut arrays = Vec::new();
        for name in names {
            if RESERVED.contains(&name.as_str()) {
                return Err(Error::InvalidParameter {
                    name: "attributes",
                    message: format!("'{name}' is the name of an array isobar computes itself; rename the particle array"),
                });
            }
            let a = data.require(name)?;
            // A NaN carried onto the surface would reach every vertex near its particle
            // (and a renderer's motion blur) without a word: refused, naming the particle.
            if let Some(i) = a.data.iter().position(|v| !v.is_finite()) {
                return Err(Error::InvalidInput(format!(
                    "array '{name}' holds a non-finite value ({}) at particle {}: it cannot \
                     be carried onto the surface",
                    a.data[i],
                    i / a.components
                )));
            }
            arrays.push((
                a.name.clone(),
                a.components,
                field.to_grid_order(&a.data, a.components),
            ));
        }
        Ok(Carried { arrays })
    }

    pub fn is_empty(&self) -> bool {
        self.arrays.is_empty()
    }

    /// The arrays at `positions`, one [`Attribute`] each, in the order they were named;
    /// one field evaluation a position. Reports progress by chunks and stops when told.
    pub fn onto<P: Copy + Into<DVec3> + Sync>(
        &self,
        field: &SphField,
        positions: &[P],
        progress: &mut Progress,
    ) -> Result<Vec<Attribute>> {
        if self.arrays.is_empty() {
            return Ok(Vec::new());
        }
        let width: usize = self.arrays.iter().map(|a| a.1).sum();
        let arrays: Vec<(&[f64], usize)> = self
            .arrays
            .iter()
            .map(|(_, c, d)| (d.as_slice(), *c))
            .collect();
        let values: Vec<f64> = chunked(positions, progress, |part| {
            let mut out = vec![0.0; part.len() * width];
            out.par_chunks_mut(width)
                .zip(part.par_iter())
                .for_each(|(row, &x)| field.interpolate(x.into(), &arrays, row));
            out
        })?;
        let mut offset = 0;
        let attributes = self
            .arrays
            .iter()
            .map(|(name, c, _)| {
                let data = values
                    .chunks_exact(width)
                    .flat_map(|row| row[offset..offset + c].iter().copied())
                    .collect();
                offset += c;
                Attribute {
                    name: name.clone(),
                    components: *c,
                    data,
                }
            })
            .collect();
        Ok(attributes)
    }
}
