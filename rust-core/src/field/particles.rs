//! Particle data as files and hosts hand it over: positions plus named per-particle arrays.
//! Nothing here knows about kernels; `field::sph` turns this into a field.

use crate::error::{Error, Result};
use glam::DVec3;

/// A named per-item array with `components` values per item (1 = scalar, 3 = vector).
#[derive(Clone, Debug, PartialEq)]
pub struct Attribute {
    pub name: String,
    pub components: usize,
    /// Item-major: item i occupies `data[i*components .. (i+1)*components]`.
    pub data: Vec<f64>,
}

impl Attribute {
    /// A scalar attribute.
    pub fn scalar(name: impl Into<String>, data: Vec<f64>) -> Self {
        Attribute {
            name: name.into(),
            components: 1,
            data,
        }
    }

    /// A 3-vector attribute from item-major triples.
    pub fn vector(name: impl Into<String>, data: Vec<[f64; 3]>) -> Self {
        Attribute {
            name: name.into(),
            components: 3,
            data: data.into_iter().flatten().collect(),
        }
    }

    /// Number of items the array describes.
    pub fn len(&self) -> usize {
        self.data.len().checked_div(self.components).unwrap_or(0)
    }

    /// True when the array holds no item.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The values of item `i`.
    pub fn item(&self, i: usize) -> &[f64] {
        &self.data[i * self.components..(i + 1) * self.components]
    }
}

/// Particles as read from a file or received from a host.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct ParticleData {
    pub positions: Vec<DVec3>,
    /// Every per-particle array the source carried (velocity, pressure, density, mass ...).
    pub attributes: Vec<Attribute>,
    /// Arrays the source held that are not per-particle data, kept by name so that asking
    /// for one says why it cannot be used instead of claiming it is not there.
    pub skipped: Vec<Skipped>,
}

/// An array a reader left out, and why ("shape (3,) for 46656 particles").
#[derive(Clone, Debug, PartialEq)]
pub struct Skipped {
    pub name: String,
    pub why: String,
}

impl ParticleData {
    /// Number of particles.
    pub fn len(&self) -> usize {
        self.positions.len()
    }

    /// True when there is no particle.
    pub fn is_empty(&self) -> bool {
        self.positions.is_empty()
    }

    /// The attribute called `name`, if present.
    pub fn attribute(&self, name: &str) -> Option<&Attribute> {
        self.attributes.iter().find(|a| a.name == name)
    }

    /// The attribute called `name`, or an error that lists what is there (or, for an
    /// array the reader left out, says why).
    pub fn require(&self, name: &str) -> Result<&Attribute> {
        self.attribute(name)
            .ok_or_else(|| match self.skipped.iter().find(|s| s.name == name) {
                Some(s) => Error::InvalidInput(format!(
                    "array '{name}' is not per-particle data: {} (usable arrays: {})",
                    s.why,
                    self.attribute_names()
                )),
                None => Error::MissingArray {
                    name: name.to_string(),
                    available: self.attribute_names(),
                },
            })
    }

    /// Comma-separated attribute names, for messages.
    pub fn attribute_names(&self) -> String {
        if self.attributes.is_empty() {
            return "none".into();
        }
        self.attributes
            .iter()
            .map(|a| a.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    /// Checks what every consumer relies on: at least one particle, finite coordinates,
    /// every array as long as the positions and finite. Errors name the first bad index.
    pub fn validate(&self) -> Result<()> {
        if self.positions.is_empty() {
            return Err(Error::InvalidInput(
                "the particle data is empty (0 particles)".into(),
            ));
        }
        if let Some(i) = self.positions.iter().position(|p| !p.is_finite()) {
            return Err(Error::InvalidInput(format!(
                "particle {i} has a non-finite position {:?}",
                self.positions[i].to_array()
            )));
        }
        for a in &self.attributes {
            if a.components == 0 || a.data.len() != a.components * self.positions.len() {
                return Err(Error::InvalidInput(format!(
                    "array '{}' has {} values for {} particles with {} components each",
                    a.name,
                    a.data.len(),
                    self.positions.len(),
                    a.components
                )));
            }
        }
        Ok(())
    }
}
