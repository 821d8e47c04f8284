//! Adaptive 3-level-grid surfaces through the C ABI. The SPH field and the isovalue come
//! from the same `IsobarSphParams` as `isobar_sph_extract` (one isovalue; `grid_factor`
//! sets the finest cell); the adaptive options sit in their own versioned struct.

use super::particles::IsobarParticles;
use super::sph::{read_params, settings, IsobarProgressFn};
use super::surface::IsobarSurface;
use super::{
    copy_versioned_out, guard, invalid, non_null, put, versioned_out_size, with_progress,
    IsobarSphParams, IsobarStatus,
};
use crate::adaptive::{self, Params};
use crate::correctors;
use crate::field::sph::carried::Carried;
use crate::field::sph::SphField;
use crate::gpu::Backend;
use std::ffi::c_void;

/// Options of `isobar_adaptive_extract`. Fill with `isobar_adaptive_params_default`,
/// which sets `struct_size`; later versions only append fields.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct IsobarAdaptiveParams {
    /// sizeof(IsobarAdaptiveParams) as the caller compiled it.
    pub struct_size: u32,
    /// Coarse cells holding 1..=this many particles become level 3 (the paper's rule: 1;
    /// default 0, none: the error criterion decides).
    pub splash_threshold: u32,
    /// Layers of neighbour cells raised to level 3 around each splash cell (0 = paper).
    pub splash_dilation: u32,
    /// Bisection halvings n on level-3 edges (n+1 on level 2, n+2 on level 1), 0..=16;
    /// 0: linear between the finest nodes, as uniform marching cubes.
    pub bisection_iterations: u32,
    /// Where the work runs: `ISOBAR_BACKEND_CPU` (default), `ISOBAR_BACKEND_GPU` (wgpu;
    /// `ISOBAR_ERR_INVALID_ARGUMENT` "no GPU adapter: ..." without one) or
    /// `ISOBAR_BACKEND_AUTO` (the GPU when an adapter exists). Added in version 2.
    pub backend: u32,
    /// Error criterion: each cell at the surface takes the lowest level whose surface lies
    /// within this many finest cells of the finest level's there (0 = off, the splash
    /// criterion alone). Added in version 3; older structs get the default.
    pub max_error: f64,
}

/// `IsobarAdaptiveParams::backend`: rayon on the CPU.
pub const ISOBAR_BACKEND_CPU: u32 = 0;
/// `IsobarAdaptiveParams::backend`: wgpu compute shaders.
pub const ISOBAR_BACKEND_GPU: u32 = 1;
/// `IsobarAdaptiveParams::backend`: the GPU when an adapter exists, else the CPU.
pub const ISOBAR_BACKEND_AUTO: u32 = 2;

/// An `ISOBAR_BACKEND_*` value of the field `name`.
pub(super) fn backend_from_c(b: u32, name: &'static str) -> Result<Backend, crate::Error> {
    match b {
        ISOBAR_BACKEND_CPU => Ok(Backend::Cpu),
        ISOBAR_BACKEND_GPU => Ok(Backend::Gpu),
        ISOBAR_BACKEND_AUTO => Ok(Backend::Auto),
        _ => Err(invalid(
            name,
            format!("{b} is not ISOBAR_BACKEND_CPU (0), _GPU (1) or _AUTO (2)"),
        )),
    }
}

/// The `ISOBAR_BACKEND_*` value of the back end that ran (`Cpu` or `Gpu`).
pub(super) fn backend_to_c(b: Backend) -> u32 {
    match b {
        Backend::Gpu => ISOBAR_BACKEND_GPU,
        _ => ISOBAR_BACKEND_CPU,
    }
}

/// Size of the first version of `IsobarAdaptiveParams`.
const ADAPTIVE_PARAMS_V1_SIZE: usize = 16;

impl Default for IsobarAdaptiveParams {
    fn default() -> Self {
        let p = Params::default();
        IsobarAdaptiveParams {
            struct_size: std::mem::size_of::<IsobarAdaptiveParams>() as u32,
            splash_threshold: p.splash_threshold,
            splash_dilation: p.splash_dilation,
            bisection_iterations: p.bisection_iterations,
            backend: ISOBAR_BACKEND_CPU,
            max_error: p.max_error,
        }
    }
}

/// What an adaptive extraction did. Set `struct_size` before the call; fields beyond it
/// are not written.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct IsobarAdaptiveStats {
    pub struct_size: u32,
    /// Coarse cells of level 1, 2, 3.
    pub cells_per_level: [u64; 3],
    /// Marching-cubes triangles from cells of level 1, 2, 3.
    pub triangles_per_level: [u64; 3],
    pub transition_faces: u64,
    pub crack_triangles: u64,
    pub vertices: u64,
    pub triangles: u64,
    pub field_evaluations: u64,
    /// Bytes of the per-level arrays.
    pub array_bytes: u64,
    pub seconds_total: f64,
    /// The back end that ran: `ISOBAR_BACKEND_CPU` or `ISOBAR_BACKEND_GPU`. Version 2.
    pub backend: u32,
}

/// Writes the default adaptive options (with `struct_size` set) to `out`.
#[no_mangle]
pub extern "C" fn isobar_adaptive_params_default(out: *mut IsobarAdaptiveParams) -> IsobarStatus {
    guard(|| put(out, IsobarAdaptiveParams::default(), "out"))
}

fn read_adaptive(p: *const IsobarAdaptiveParams) -> Result<IsobarAdaptiveParams, crate::Error> {
    super::read_versioned(
        p,
        "adaptive",
        ADAPTIVE_PARAMS_V1_SIZE,
        "isobar_adaptive_params_default",
    )
}

/// Extracts the adaptive crack-free surface of the particles' SPH field, carrying the
/// particle arrays `sph->attributes` names onto its vertices as `isobar_sph_extract` does
/// (the other Marching Correctors options of `sph` are not used). `progress` and
/// `stats` may be NULL. On success `*out` owns a surface to free with
/// `isobar_surface_free` (its `isobar_surface_stats` carries vertices, triangles, field
/// evaluations and total time); on failure `*out` is left untouched.
#[no_mangle]
pub extern "C" fn isobar_adaptive_extract(
    particles: *const IsobarParticles,
    sph: *const IsobarSphParams,
    adaptive: *const IsobarAdaptiveParams,
    progress: IsobarProgressFn,
    user: *mut c_void,
    out: *mut *mut IsobarSurface,
    stats: *mut IsobarAdaptiveStats,
) -> IsobarStatus {
    guard(|| {
        let particles = non_null(particles, "particles")?;
        if out.is_null() {
            return Err(invalid("out", "output pointer must not be NULL"));
        }
        let p = read_params(sph)?;
        let a = read_adaptive(adaptive)?;
        // A bad stats struct fails here, not after the extraction it would have reported.
        if !stats.is_null() {
            versioned_out_size(stats, "stats")?;
        }
        let (field_settings, sph_params) = settings(&p)?;
        let [isovalue] = sph_params.isovalues[..] else {
            return Err(invalid(
                "params.isovalues",
                format!(
                    "the adaptive surface takes exactly one isovalue, got {}",
                    sph_params.isovalues.len()
                ),
            ));
        };
        let params = Params {
            isovalue,
            grid_factor: sph_params.grid_factor,
            splash_threshold: a.splash_threshold,
            splash_dilation: a.splash_dilation,
            max_error: a.max_error,
            // Not in the C struct (its layout is versioned): always the default, on.
            hidden_surfaces: Params::default().hidden_surfaces,
            bisection_iterations: a.bisection_iterations,
            normals: sph_params.normals,
            memory_budget: sph_params.memory_budget,
            backend: backend_from_c(a.backend, "adaptive.backend")?,
        };
        let extraction = with_progress(progress, user, |sink| {
            sink.window(0.0, 0.1);
            let field = SphField::build(&particles.data, &field_settings, sink)?;
            // A missing array is refused before the surface is made.
            let carried = Carried::new(&field, &particles.data, &sph_params.attributes)?;
            adaptive::extract_sph_carrying(&field, &carried, &params, (0.1, 1.0), sink)
        })?;
        let s = &extraction.stats;
        if !stats.is_null() {
            let full = IsobarAdaptiveStats {
                struct_size: 0,
                cells_per_level: s.cells_per_level,
                triangles_per_level: s.triangles_per_level,
                transition_faces: s.transition_faces,
                crack_triangles: s.crack_triangles,
                vertices: s.vertices,
                triangles: s.triangles,
                field_evaluations: s.field_evaluations,
                array_bytes: s.array_bytes,
                seconds_total: s.timings.total,
                backend: backend_to_c(s.backend),
            };
            copy_versioned_out(full, stats, "stats")?;
        }
        let legacy = correctors::Extraction {
            stats: correctors::Stats {
                vertices: s.vertices,
                triangles: s.triangles,
                field_evaluations: s.field_evaluations,
                backend: s.backend,
                timings: correctors::Timings {
                    total: s.timings.total,
                    ..correctors::Timings::default()
                },
                warnings: s.warnings.clone(),
                ..correctors::Stats::default()
            },
            mesh: extraction.mesh,
        };
        put(out, Box::into_raw(IsobarSurface::new(legacy)), "out")
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::capi::{
        isobar_particles_add_array, isobar_particles_create, isobar_particles_free,
        isobar_surface_attribute, isobar_surface_attribute_count, isobar_surface_free,
        isobar_surface_triangle_count, isobar_surface_vertex_count,
    };
    use crate::field::particles::ParticleData;
    use crate::field::sph::{SmoothingLength, SphSettings};
    use crate::progress::Progress;
    use glam::DVec3;

    fn ball() -> Vec<DVec3> {
        let mut p = Vec::new();
        for z in -6i32..=6 {
            for y in -6i32..=6 {
                for x in -6i32..=6 {
                    let v = DVec3::new(x as f64, y as f64, z as f64) * 0.1;
                    if v.length() <= 0.6 {
                        p.push(v);
                    }
                }
            }
        }
        p.push(DVec3::new(1.4, 0.0, 0.0));
        p
    }

    #[test]
    fn c_entry_point_equals_the_rust_api_and_reports_errors() {
        let positions = ball();
        let flat: Vec<f64> = positions.iter().flat_map(|p| p.to_array()).collect();
        let mut handle = std::ptr::null_mut();
        assert_eq!(
            isobar_particles_create(flat.as_ptr(), positions.len(), &mut handle),
            IsobarStatus::Ok
        );
        let iso = [0.5f64];
        let mut sph = IsobarSphParams {
            h: 0.2,
            isovalues: iso.as_ptr(),
            isovalue_count: 1,
            ..IsobarSphParams::default()
        };
        let mut adaptive = IsobarAdaptiveParams::default();
        assert_eq!(
            isobar_adaptive_params_default(&mut adaptive),
            IsobarStatus::Ok
        );
        let mut stats = IsobarAdaptiveStats {
            struct_size: std::mem::size_of::<IsobarAdaptiveStats>() as u32,
            ..IsobarAdaptiveStats::default()
        };
        let mut surface = std::ptr::null_mut();
        let status = isobar_adaptive_extract(
            handle,
            &sph,
            &adaptive,
            None,
            std::ptr::null_mut(),
            &mut surface,
            &mut stats,
        );
        assert_eq!(status, IsobarStatus::Ok);
        // The same extraction through the Rust API.
        let data = ParticleData {
            positions: positions.clone(),
            attributes: vec![],
            ..Default::default()
        };
        let field = SphField::new(
            &data,
            &SphSettings {
                smoothing_length: SmoothingLength::Constant(0.2),
                ..SphSettings::default()
            },
        )
        .unwrap();
        let rust =
            adaptive::extract_sph(&field, &Params::default(), &mut Progress::none()).unwrap();
        assert_eq!(
            isobar_surface_triangle_count(surface),
            rust.mesh.triangles.len()
        );
        assert_eq!(
            isobar_surface_vertex_count(surface),
            rust.mesh.vertex_count()
        );
        assert_eq!(stats.triangles as usize, rust.mesh.triangles.len());
        assert_eq!(stats.cells_per_level, rust.stats.cells_per_level);
        assert!(stats.cells_per_level[2] > 0, "the droplet is level 3");
        assert_eq!(isobar_surface_attribute_count(surface), 0);
        isobar_surface_free(surface);
        // The arrays `sph.attributes` names reach the vertices (a constant one stays
        // constant); a missing one is refused.
        let sevens = vec![7.0; positions.len()];
        let name = c"seven";
        assert_eq!(
            isobar_particles_add_array(handle, name.as_ptr(), sevens.as_ptr(), sevens.len(), 1),
            IsobarStatus::Ok
        );
        for (names, expect) in [
            ([name.as_ptr()], IsobarStatus::Ok),
            ([c"none".as_ptr()], IsobarStatus::ErrInvalidInput),
        ] {
            let with = IsobarSphParams {
                attributes: names.as_ptr(),
                attribute_count: 1,
                ..sph
            };
            let mut carried = std::ptr::null_mut();
            let status = isobar_adaptive_extract(
                handle,
                &with,
                &adaptive,
                None,
                std::ptr::null_mut(),
                &mut carried,
                std::ptr::null_mut(),
            );
            assert_eq!(status, expect);
            if status != IsobarStatus::Ok {
                assert!(carried.is_null());
                continue;
            }
            assert_eq!(
                isobar_surface_vertex_count(carried),
                rust.mesh.vertex_count()
            );
            assert_eq!(isobar_surface_attribute_count(carried), 1);
            let (mut n, mut c, mut d) = (std::ptr::null(), 0usize, std::ptr::null());
            assert_eq!(
                isobar_surface_attribute(carried, 0, &mut n, &mut c, &mut d),
                IsobarStatus::Ok
            );
            // SAFETY: the surface owns a vertex_count-long array and a NUL-terminated name.
            let values = unsafe { std::slice::from_raw_parts(d, rust.mesh.vertex_count()) };
            assert_eq!(unsafe { std::ffi::CStr::from_ptr(n) }, name);
            assert_eq!(c, 1);
            assert!(values.iter().all(|v| (v - 7.0).abs() < 1e-12), "{values:?}");
            isobar_surface_free(carried);
        }
        // Refused calls return nothing and leave `out` untouched.
        let refused = |sph: &IsobarSphParams, adaptive: &IsobarAdaptiveParams| {
            let mut none = std::ptr::null_mut();
            let status = isobar_adaptive_extract(
                handle,
                sph,
                adaptive,
                None,
                std::ptr::null_mut(),
                &mut none,
                std::ptr::null_mut(),
            );
            assert!(none.is_null());
            status
        };
        // Two isovalues.
        let two = [0.5f64, 0.6];
        sph.isovalues = two.as_ptr();
        sph.isovalue_count = 2;
        assert_eq!(refused(&sph, &adaptive), IsobarStatus::ErrInvalidArgument);
        // A struct_size from nowhere.
        sph.isovalue_count = 1;
        adaptive.struct_size = 3;
        assert_eq!(refused(&sph, &adaptive), IsobarStatus::ErrInvalidArgument);
        // An unknown back end; a version-1 struct (no backend field) runs on the CPU.
        adaptive = IsobarAdaptiveParams {
            backend: 7,
            ..IsobarAdaptiveParams::default()
        };
        assert_eq!(refused(&sph, &adaptive), IsobarStatus::ErrInvalidArgument);
        adaptive.struct_size = ADAPTIVE_PARAMS_V1_SIZE as u32;
        let mut surface = std::ptr::null_mut();
        let status = isobar_adaptive_extract(
            handle,
            &sph,
            &adaptive,
            None,
            std::ptr::null_mut(),
            &mut surface,
            &mut stats,
        );
        assert_eq!(status, IsobarStatus::Ok);
        assert_eq!(stats.backend, ISOBAR_BACKEND_CPU);
        isobar_surface_free(surface);
        let v1_triangles = stats.triangles;
        // max_error (version 3): a bad value is refused by name; a version-2 struct (up
        // to `backend`) gets the default whatever lies beyond it, as version 1 did.
        adaptive = IsobarAdaptiveParams {
            max_error: -1.0,
            ..IsobarAdaptiveParams::default()
        };
        assert_eq!(refused(&sph, &adaptive), IsobarStatus::ErrInvalidArgument);
        // SAFETY: the message is a NUL-terminated string valid until the next call.
        let message =
            unsafe { std::ffi::CStr::from_ptr(super::super::isobar_last_error_message()) };
        assert!(
            message.to_string_lossy().contains("max_error"),
            "{message:?}"
        );
        adaptive.struct_size = std::mem::offset_of!(IsobarAdaptiveParams, max_error) as u32;
        let mut surface = std::ptr::null_mut();
        let status = isobar_adaptive_extract(
            handle,
            &sph,
            &adaptive,
            None,
            std::ptr::null_mut(),
            &mut surface,
            &mut stats,
        );
        assert_eq!(status, IsobarStatus::Ok);
        assert_eq!(stats.triangles, v1_triangles);
        isobar_surface_free(surface);
        // A stats struct of a bad size is refused before any work: progress never runs.
        extern "C" fn count_calls(user: *mut c_void, _: f64, _: *const std::ffi::c_char) -> i32 {
            // SAFETY: `user` is the counter below, alive for the call.
            unsafe { *user.cast::<u32>() += 1 };
            0
        }
        // (status, surface, progress calls) of an extraction that fills a stats struct
        // of `struct_size` bytes.
        let counted = |struct_size: usize| {
            let (mut calls, mut surface) = (0u32, std::ptr::null_mut());
            let mut stats = IsobarAdaptiveStats {
                struct_size: struct_size as u32,
                ..IsobarAdaptiveStats::default()
            };
            let status = isobar_adaptive_extract(
                handle,
                &sph,
                &IsobarAdaptiveParams::default(),
                Some(count_calls),
                (&mut calls as *mut u32).cast(),
                &mut surface,
                &mut stats,
            );
            (status, surface, calls)
        };
        let (status, none, calls) = counted(2);
        assert_eq!(status, IsobarStatus::ErrInvalidArgument);
        assert!(none.is_null());
        assert_eq!(
            calls, 0,
            "the extraction ran before the stats struct was checked"
        );
        // The same call with a good struct does report progress (so 0 above means "no work").
        let (status, surface, calls) = counted(std::mem::size_of::<IsobarAdaptiveStats>());
        assert_eq!(status, IsobarStatus::Ok);
        assert!(calls > 0);
        isobar_surface_free(surface);
        isobar_particles_free(handle);
    }
}
