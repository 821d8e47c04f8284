//! An [`SphField`] on the device: its particles (grid-slot order, positions relative to
//! an origin so f32 keeps their precision), its neighbour grid's offsets and the uniform
//! the kernels of `shaders/sph.wgsl` read.

use super::device::Gpu;
use crate::error::{Error, Result};
use crate::field::kernel::Kernel;
use crate::field::sph::SphField;
use glam::DVec3;

/// `Particle` of sph.wgsl.
#[repr(C)]
#[derive(Clone, Copy)]
struct Particle {
    pos: [f32; 3],
    support2: f32,
    inv_h: f32,
    weight_scale: f32,
    value: f32,
    pad: f32,
}

/// `Field` of sph.wgsl.
#[repr(C)]
#[derive(Clone, Copy)]
struct FieldUniform {
    origin: [f32; 3],
    inv_cell: f32,
    dims: [u32; 3],
    kernel: u32,
    shepard: u32,
    reach: u32,
    pad: [u32; 2],
}

/// The field's buffers, bound at group 0, bindings 0–2, by every kernel that evaluates it.
pub struct GpuField {
    pub particles: wgpu::Buffer,
    pub offsets: wgpu::Buffer,
    pub uniform: wgpu::Buffer,
    /// Subtracted from every position before the conversion to f32.
    pub origin: DVec3,
}

impl GpuField {
    /// Uploads `field` with positions taken relative to `origin`.
    pub fn new(gpu: &Gpu, field: &SphField, origin: DVec3) -> Result<GpuField> {
        let particles: Vec<Particle> = (0..field.len())
            .map(|slot| {
                let (pos, support2, inv_h, weight_scale, value) = field.packed(slot);
                Particle {
                    pos: (pos - origin).as_vec3().to_array(),
                    support2: support2 as f32,
                    inv_h: inv_h as f32,
                    weight_scale: weight_scale as f32,
                    value: value as f32,
                    pad: 0.0,
                }
            })
            .collect();
        if let Some(i) = particles.iter().position(|p| {
            !(p.weight_scale.is_finite() && p.value.is_finite() && p.support2.is_finite())
        }) {
            return Err(Error::InvalidInput(format!(
                "particle slot {i} does not fit f32 on the GPU (weight {}, value {})",
                field.packed(i).3,
                field.packed(i).4
            )));
        }
        let (ng_origin, inv_cell, dims, offsets) =
            field.neighbour_grid().layout().ok_or_else(|| {
                Error::InvalidInput(
                    "the particles lie far apart (a grid over their bounding box would be \
                     mostly empty): the GPU's neighbour grid cannot skip the empty space; \
                     use the CPU back end (--backend cpu)"
                        .into(),
                )
            })?;
        let uniform = FieldUniform {
            origin: (ng_origin - origin).as_vec3().to_array(),
            inv_cell: inv_cell as f32,
            dims: dims.map(|d| d as u32),
            kernel: match field.kernel() {
                Kernel::CubicSpline => 0,
                Kernel::WendlandC2 => 1,
                Kernel::QuinticSpline => 2,
                Kernel::Quadratic => 3,
            },
            shepard: field.shepard() as u32,
            reach: field.search_reach(),
            pad: [0; 2],
        };
        Ok(GpuField {
            particles: gpu.upload("particles", &particles),
            offsets: gpu.upload("neighbour offsets", offsets),
            uniform: gpu.uniform("field", &uniform),
            origin,
        })
    }

    /// The (binding, buffer) pairs of the field.
    pub fn bindings(&self) -> [(u32, &wgpu::Buffer); 3] {
        [(0, &self.particles), (1, &self.offsets), (2, &self.uniform)]
    }
}

// SAFETY: plain `repr(C)` structs of 4-byte scalars without padding; any bits are valid.
unsafe impl bytemuck::Zeroable for Particle {}
unsafe impl bytemuck::Pod for Particle {}
unsafe impl bytemuck::Zeroable for FieldUniform {}
unsafe impl bytemuck::Pod for FieldUniform {}
