//! SPH extraction through the C ABI: a versioned parameter struct and one entry point.

use super::particles::IsobarParticles;
use super::surface::IsobarSurface;
use super::{guard, invalid, non_null, opt_str, put, slice, with_progress, IsobarStatus};
use crate::correctors::{self, Lattice, Params, Trim};
use crate::field::kernel::Kernel;
use crate::field::sph::{Mass, Quantity, SmoothingLength, SphField, SphSettings, Volumes};
use crate::field::DEFAULT_MEMORY_BUDGET;
use glam::DVec3;
use std::ffi::{c_char, c_void};

/// Kernel: Monaghan's cubic spline (support 2h).
pub const ISOBAR_KERNEL_CUBIC: u32 = 0;
/// Kernel: Wendland C2 (support 2h).
pub const ISOBAR_KERNEL_WENDLAND: u32 = 1;
/// Kernel: Morris' quintic spline (support 3h).
pub const ISOBAR_KERNEL_QUINTIC: u32 = 2;
/// Kernel: Johnson's quadratic kernel (support 2h).
pub const ISOBAR_KERNEL_QUADRATIC: u32 = 3;

/// Parameters of `isobar_sph_extract`. Fill with `isobar_sph_params_default`, which sets
/// `struct_size`; later library versions only append fields, so old callers keep working.
/// Strings are NUL-terminated UTF-8, NULL meaning "not given".
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct IsobarSphParams {
    /// sizeof(IsobarSphParams) as the caller compiled it.
    pub struct_size: u32,
    /// One of the ISOBAR_KERNEL_* values.
    pub kernel: u32,
    /// Constant smoothing length, used when `h_array` is NULL.
    pub h: f64,
    /// Per-particle smoothing length array.
    pub h_array: *const c_char,
    /// Multiplies every smoothing length (1, 0.75, 0.5 ...).
    pub h_scale: f64,
    /// Field: array name, "NAME:mag", "NAME:K", or NULL / "SumOfWeights" for the free surface.
    pub field: *const c_char,
    /// Per-particle volume array (m/ρ); wins over density.
    pub volume_array: *const c_char,
    /// Density array; volumes = mass / density.
    pub density_array: *const c_char,
    /// Per-particle mass array.
    pub mass_array: *const c_char,
    /// Constant mass when > 0 and `mass_array` is NULL.
    pub mass: f64,
    /// Non-zero: divide by the sum of weights.
    pub shepard: i32,
    /// Non-zero: correct vertices onto the level set; zero: preview.
    pub correct: i32,
    /// Isovalues (at least one).
    pub isovalues: *const f64,
    pub isovalue_count: usize,
    /// Virtual cell size in units of the smallest h.
    pub grid_factor: f64,
    /// Relative tolerance of the correction.
    pub tolerance: f64,
    /// Non-zero: trim at free surfaces with the thresholds below.
    pub trim: i32,
    pub trim_node: f64,
    pub trim_vertex: f64,
    /// Non-zero: compute vertex normals.
    pub normals: i32,
    /// Names of particle arrays to interpolate onto the surface.
    pub attributes: *const *const c_char,
    pub attribute_count: usize,
    /// Bytes that extent-sized structures may use.
    pub memory_budget: u64,
    /// Non-zero: the full-grid resampling baseline instead of Marching Correctors.
    pub full_grid: i32,
    // ---- end of ABI 1 (SPH_PARAMS_V1_SIZE); fields below keep their defaults for
    // callers whose struct_size stops before them.
    /// Non-zero: put the virtual grid on the lattice `lattice_origin + (i,j,k) ·
    /// lattice_cell_size` instead of grid_factor × smallest h, so pieces of a
    /// data-parallel run share their grid nodes.
    pub fixed_lattice: i32,
    pub lattice_origin: [f64; 3],
    pub lattice_cell_size: f64,
    /// Non-zero: keep only the surface in cells whose lowest corner lies in the
    /// half-open box [clip_min, clip_max); particles outside it still shape the field.
    pub clip: i32,
    pub clip_min: [f64; 3],
    pub clip_max: [f64; 3],
    // ---- end of ABI 2 (SPH_PARAMS_V2_SIZE).
    /// Where Marching Correctors' seed-cell neighbour search runs: `ISOBAR_BACKEND_CPU`
    /// (default), `ISOBAR_BACKEND_GPU` (wgpu; `ISOBAR_ERR_INVALID_ARGUMENT` "no GPU
    /// adapter: ..." without one) or `ISOBAR_BACKEND_AUTO` (a hardware GPU when there is
    /// one, else the CPU). Every back end gives the same surface; `IsobarStats::backend`
    /// says which ran. The full-grid baseline refuses `ISOBAR_BACKEND_GPU`;
    /// `isobar_adaptive_extract` takes its back end from `IsobarAdaptiveParams` instead.
    pub backend: u32,
}

/// Size of the ABI-1 parameter struct: the smallest `struct_size` ever accepted. Fields
/// added later go after it and keep their defaults for callers that predate them.
const SPH_PARAMS_V1_SIZE: usize = 176;
/// Size of the ABI-2 struct (lattice and clip box, no `backend`): callers built against
/// it run on the CPU.
#[cfg(test)]
const SPH_PARAMS_V2_SIZE: usize = 264;

/// Progress callback: fraction in [0, 1] and a phase name; return non-zero to cancel.
pub type IsobarProgressFn =
    Option<extern "C" fn(user: *mut c_void, fraction: f64, phase: *const c_char) -> i32>;

impl Default for IsobarSphParams {
    fn default() -> Self {
        let p = Params::default();
        let t = Trim::default();
        IsobarSphParams {
            struct_size: std::mem::size_of::<IsobarSphParams>() as u32,
            kernel: ISOBAR_KERNEL_CUBIC,
            h: 0.0,
            h_array: std::ptr::null(),
            h_scale: 1.0,
            field: std::ptr::null(),
            volume_array: std::ptr::null(),
            density_array: std::ptr::null(),
            mass_array: std::ptr::null(),
            mass: 0.0,
            shepard: 0,
            correct: 1,
            isovalues: std::ptr::null(),
            isovalue_count: 0,
            grid_factor: p.grid_factor,
            tolerance: p.tolerance,
            trim: 1,
            trim_node: t.node,
            trim_vertex: t.vertex,
            normals: 1,
            attributes: std::ptr::null(),
            attribute_count: 0,
            memory_budget: DEFAULT_MEMORY_BUDGET,
            full_grid: 0,
            fixed_lattice: 0,
            lattice_origin: [0.0; 3],
            lattice_cell_size: 0.0,
            clip: 0,
            clip_min: [0.0; 3],
            clip_max: [0.0; 3],
            backend: super::adaptive::ISOBAR_BACKEND_CPU,
        }
    }
}

/// Writes the default parameters (with `struct_size` set) to `out`.
#[no_mangle]
pub extern "C" fn isobar_sph_params_default(out: *mut IsobarSphParams) -> IsobarStatus {
    guard(|| put(out, IsobarSphParams::default(), "out"))
}

/// The caller's struct over the defaults: fields beyond its `struct_size` keep defaults.
pub(super) fn read_params(params: *const IsobarSphParams) -> Result<IsobarSphParams, crate::Error> {
    super::read_versioned(
        params,
        "params",
        SPH_PARAMS_V1_SIZE,
        "isobar_sph_params_default",
    )
}

pub(super) fn settings(p: &IsobarSphParams) -> Result<(SphSettings, Params), crate::Error> {
    let kernel = match p.kernel {
        ISOBAR_KERNEL_CUBIC => Kernel::CubicSpline,
        ISOBAR_KERNEL_WENDLAND => Kernel::WendlandC2,
        ISOBAR_KERNEL_QUINTIC => Kernel::QuinticSpline,
        ISOBAR_KERNEL_QUADRATIC => Kernel::Quadratic,
        k => {
            return Err(invalid(
                "params.kernel",
                format!("{k} is not an ISOBAR_KERNEL_* value"),
            ))
        }
    };
    let smoothing_length = match opt_str(p.h_array, "params.h_array")? {
        Some(name) => SmoothingLength::Array(name),
        None => SmoothingLength::Constant(p.h),
    };
    let mass = match opt_str(p.mass_array, "params.mass_array")? {
        Some(name) => Some(Mass::Array(name)),
        None if p.mass == 0.0 => None,
        None if p.mass > 0.0 && p.mass.is_finite() => Some(Mass::Constant(p.mass)),
        None => {
            return Err(invalid(
                "params.mass",
                format!("must be positive (or 0 for none), got {}", p.mass),
            ))
        }
    };
    let volumes = match (
        opt_str(p.volume_array, "params.volume_array")?,
        opt_str(p.density_array, "params.density_array")?,
    ) {
        (Some(v), _) => Volumes::Array(v),
        (None, Some(rho)) => Volumes::MassDensity {
            mass: mass.ok_or_else(|| {
                invalid(
                    "params.mass",
                    "volumes from a density array need a mass (mass or mass_array)",
                )
            })?,
            density: rho,
        },
        (None, None) => Volumes::Computed { mass },
    };
    let quantity = match opt_str(p.field, "params.field")? {
        Some(f) if !f.is_empty() => Quantity::parse(&f),
        _ => Quantity::SumOfWeights,
    };
    let names = slice(p.attributes, p.attribute_count, "params.attributes")?;
    let attributes = names
        .iter()
        .map(|&n| {
            opt_str(n, "params.attributes")?
                .ok_or_else(|| invalid("params.attributes", "contains NULL"))
        })
        .collect::<Result<Vec<_>, _>>()?;
    let sph = SphSettings {
        kernel,
        smoothing_length,
        h_scale: p.h_scale,
        volumes,
        quantity,
        shepard: p.shepard != 0,
        memory_budget: p.memory_budget,
    };
    let params = Params {
        memory_budget: p.memory_budget,
        lattice: (p.fixed_lattice != 0).then_some(Lattice {
            origin: DVec3::from(p.lattice_origin),
            cell_size: p.lattice_cell_size,
        }),
        clip: (p.clip != 0).then_some((DVec3::from(p.clip_min), DVec3::from(p.clip_max))),
        isovalues: slice(p.isovalues, p.isovalue_count, "params.isovalues")?.to_vec(),
        grid_factor: p.grid_factor,
        correct: p.correct != 0,
        tolerance: p.tolerance,
        trim: (p.trim != 0).then_some(Trim {
            node: p.trim_node,
            vertex: p.trim_vertex,
        }),
        normals: p.normals != 0,
        attributes,
        backend: super::adaptive::backend_from_c(p.backend, "params.backend")?,
    };
    Ok((sph, params))
}

/// Extracts isosurfaces of the particles' SPH field. `progress` may be NULL; it is called
/// on the calling thread only. On success `*out` owns a surface to free with
/// `isobar_surface_free`; on failure `*out` is left untouched.
#[no_mangle]
pub extern "C" fn isobar_sph_extract(
    particles: *const IsobarParticles,
    params: *const IsobarSphParams,
    progress: IsobarProgressFn,
    user: *mut c_void,
    out: *mut *mut IsobarSurface,
) -> IsobarStatus {
    guard(|| {
        let particles = non_null(particles, "particles")?;
        if out.is_null() {
            return Err(invalid("out", "output pointer must not be NULL"));
        }
        let p = read_params(params)?;
        let (sph, params) = settings(&p)?;
        let data = &particles.data;
        let extraction = with_progress(progress, user, |sink| {
            sink.window(0.0, 0.1);
            let field = SphField::build(data, &sph, sink)?;
            sink.window(0.1, 1.0);
            if p.full_grid != 0 {
                crate::baseline::extract(&field, data, &params, sink)
            } else {
                correctors::extract(&field, data, &params, sink)
            }
        })?;
        put(out, Box::into_raw(IsobarSurface::new(extraction)), "out")
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn abi_1_struct_size_is_frozen() {
        // Every ABI-1 field lies inside the ABI-1 size; later fields may only follow it.
        let end_of_v1_fields = std::mem::offset_of!(IsobarSphParams, full_grid) + 4;
        assert!(end_of_v1_fields <= SPH_PARAMS_V1_SIZE);
        assert!(SPH_PARAMS_V1_SIZE <= std::mem::size_of::<IsobarSphParams>());
        assert_eq!(
            SPH_PARAMS_V1_SIZE % std::mem::align_of::<IsobarSphParams>(),
            0
        );
        // ABI 2 ends where `backend` begins.
        assert_eq!(
            std::mem::offset_of!(IsobarSphParams, backend),
            SPH_PARAMS_V2_SIZE
        );
    }

    /// `backend`: checked, reported in `IsobarStats::backend`, absent from ABI-2 structs
    /// (which run on the CPU), refused by the full-grid baseline when it asks for the GPU;
    /// ABI-1 stats structs (no `backend`) are still filled.
    #[test]
    fn backend_field_is_versioned_checked_and_reported() {
        use crate::capi::{
            isobar_particles_create, isobar_particles_free, isobar_surface_free,
            isobar_surface_stats, IsobarStats, IsobarStatus, ISOBAR_BACKEND_CPU,
            ISOBAR_BACKEND_GPU,
        };
        let mut flat = Vec::new();
        for z in -4i32..=4 {
            for y in -4i32..=4 {
                for x in -4i32..=4 {
                    flat.extend([x as f64 * 0.1, y as f64 * 0.1, z as f64 * 0.1]);
                }
            }
        }
        let mut handle = std::ptr::null_mut();
        assert_eq!(
            isobar_particles_create(flat.as_ptr(), flat.len() / 3, &mut handle),
            IsobarStatus::Ok
        );
        let iso = [0.5f64];
        let params = IsobarSphParams {
            h: 0.2,
            isovalues: iso.as_ptr(),
            isovalue_count: 1,
            ..IsobarSphParams::default()
        };
        let run = |p: &IsobarSphParams| {
            let mut surface = std::ptr::null_mut();
            let status = isobar_sph_extract(handle, p, None, std::ptr::null_mut(), &mut surface);
            (status, surface)
        };
        let stats_of = |surface, size: usize| {
            let mut stats = IsobarStats {
                struct_size: size as u32,
                backend: 99,
                ..IsobarStats::default()
            };
            assert_eq!(isobar_surface_stats(surface, &mut stats), IsobarStatus::Ok);
            stats
        };
        let full = std::mem::size_of::<IsobarStats>();
        // Default: the CPU, reported.
        let (status, surface) = run(&params);
        assert_eq!(status, IsobarStatus::Ok);
        assert_eq!(stats_of(surface, full).backend, ISOBAR_BACKEND_CPU);
        // A stats struct from before `backend` gets its prefix only.
        let v1 = stats_of(surface, std::mem::offset_of!(IsobarStats, backend));
        assert_eq!(v1.backend, 99);
        assert!(v1.triangles > 0);
        isobar_surface_free(surface);
        // An ABI-2 caller's struct ends before `backend`: whatever follows is not read.
        let v2 = IsobarSphParams {
            struct_size: SPH_PARAMS_V2_SIZE as u32,
            backend: 7,
            ..params
        };
        let (status, surface) = run(&v2);
        assert_eq!(status, IsobarStatus::Ok);
        assert_eq!(stats_of(surface, full).backend, ISOBAR_BACKEND_CPU);
        isobar_surface_free(surface);
        // An unknown value, and the GPU for the CPU-only baseline, are refused.
        for bad in [
            IsobarSphParams {
                backend: 7,
                ..params
            },
            IsobarSphParams {
                backend: ISOBAR_BACKEND_GPU,
                full_grid: 1,
                ..params
            },
        ] {
            let (status, surface) = run(&bad);
            assert_eq!(status, IsobarStatus::ErrInvalidArgument);
            assert!(surface.is_null());
        }
        isobar_particles_free(handle);
    }
}
