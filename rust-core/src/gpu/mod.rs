//! The wgpu back end: one lazily created device (adapter, device, queue, a pipeline
//! cache), buffer helpers, and the WGSL kernels of the adaptive 3-level method
//! (`shaders/*.wgsl`). With no adapter (or a build without the `gpu` feature) an explicit
//! [`Backend::Gpu`] request is an error saying so, and [`Backend::Auto`] runs on the CPU.
//!
//! Kernels compute in f32 (WGSL has no portable f64): field values differ from the CPU's
//! f64 ones by a relative ~1e-6. A finest node whose value lies within a margin (1/256 of
//! the field's scale) of the isovalue takes the CPU's side from a table the host computes
//! in f64 (`sides`), so GPU and CPU surfaces have the same triangles, their vertices
//! within ~3e-6 on the shipped frames.

use crate::error::{Error, Result};

/// A kernel module's WGSL source as `(name, text)`: `shaders/sph.wgsl` (the particle
/// layout and neighbour loop every kernel uses) followed by the module's own files, joined
/// once per process.
#[cfg(feature = "gpu")]
macro_rules! kernel_source {
    ($name:literal, $($file:literal),+) => {{
        static SOURCE: std::sync::OnceLock<String> = std::sync::OnceLock::new();
        let text = SOURCE.get_or_init(|| {
            [include_str!("shaders/sph.wgsl"), $(include_str!(concat!("shaders/", $file))),+]
                .join("\n")
        });
        ($name, text.as_str())
    }};
}

#[cfg(feature = "gpu")]
pub mod cracks;
#[cfg(feature = "gpu")]
pub mod device;
#[cfg(feature = "gpu")]
pub mod level;
#[cfg(feature = "gpu")]
pub mod register;
#[cfg(feature = "gpu")]
pub mod seeds;
#[cfg(feature = "gpu")]
pub mod sides;
#[cfg(feature = "gpu")]
pub mod sph;

/// Where an extraction runs.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum Backend {
    /// Rayon on the CPU, f64 throughout.
    #[default]
    Cpu,
    /// wgpu compute shaders; an error when no adapter exists.
    Gpu,
    /// A hardware GPU when there is one, else the CPU (a software adapter such as
    /// lavapipe is correct but slower than the CPU path; ask for `Gpu` to use it).
    Auto,
}

impl Backend {
    /// Parses `cpu`, `gpu` or `auto`.
    pub fn parse(s: &str) -> Result<Backend> {
        match s.to_ascii_lowercase().as_str() {
            "cpu" => Ok(Backend::Cpu),
            "gpu" => Ok(Backend::Gpu),
            "auto" => Ok(Backend::Auto),
            _ => Err(Error::InvalidParameter {
                name: "backend",
                message: format!("'{s}' is not one of cpu, gpu, auto"),
            }),
        }
    }

    /// Name used on command lines and in stats.
    pub fn name(self) -> &'static str {
        match self {
            Backend::Cpu => "cpu",
            Backend::Gpu => "gpu",
            Backend::Auto => "auto",
        }
    }

    /// The back end that will actually run: `Cpu` or `Gpu`. `Gpu` without an adapter is
    /// an error naming why there is none; `Auto` then gives `Cpu`.
    pub fn resolve(self) -> Result<Backend> {
        match self {
            Backend::Cpu => Ok(Backend::Cpu),
            Backend::Gpu => adapter_name().map(|_| Backend::Gpu),
            Backend::Auto => Ok(if hardware_adapter() {
                Backend::Gpu
            } else {
                Backend::Cpu
            }),
        }
    }
}

/// True when the adapter is a hardware GPU (not a software rasteriser).
fn hardware_adapter() -> bool {
    auto_fallback_reason().is_none()
}

/// Why [`Backend::Auto`] runs on the CPU on this machine, for hosts to tell their user
/// ("no GPU adapter: ..." or a software rasteriser only); `None` when it picks a GPU.
pub fn auto_fallback_reason() -> Option<String> {
    #[cfg(feature = "gpu")]
    {
        match device::get() {
            Err(e) => Some(e.to_string()),
            Ok(g) if g.software => Some(format!(
                "the only GPU adapter, {}, is a software rasteriser (slower than the CPU path)",
                g.name
            )),
            Ok(_) => None,
        }
    }
    #[cfg(not(feature = "gpu"))]
    {
        Some(
            adapter_name()
                .expect_err("no adapter without the feature")
                .to_string(),
        )
    }
}

/// Name and driver of the adapter the GPU back end uses, or an error saying why there is
/// none ("no GPU adapter: ...").
pub fn adapter_name() -> Result<String> {
    #[cfg(feature = "gpu")]
    {
        device::get().map(|g| g.name.clone())
    }
    #[cfg(not(feature = "gpu"))]
    {
        Err(no_adapter(
            "this build of isobar has no GPU support (feature 'gpu' is off)",
        ))
    }
}

/// The error of a GPU request that cannot be served.
pub(crate) fn no_adapter(why: &str) -> Error {
    Error::InvalidParameter {
        name: "backend",
        message: format!("no GPU adapter: {why}"),
    }
}

#[cfg(all(test, feature = "gpu"))]
mod tests;

/// The CPU-only build (`--no-default-features`), run by `scripts/test-all.sh` with
/// `cargo test --no-default-features --lib no_gpu`: a GPU request gets the same clear
/// error from every entry point, never a panic, and `Auto` runs on the CPU.
#[cfg(all(test, not(feature = "gpu")))]
mod no_gpu_tests {
    use super::Backend;
    use crate::field::particles::ParticleData;
    use crate::field::sph::{SmoothingLength, SphField, SphSettings};
    use crate::progress::Progress;
    use crate::{adaptive, correctors};
    use glam::DVec3;

    fn assert_no_gpu(e: crate::error::Error) {
        let text = e.to_string();
        assert!(
            text.contains("no GPU adapter") && text.contains("feature 'gpu' is off"),
            "{text}"
        );
    }

    #[test]
    fn no_gpu_requests_are_refused_and_auto_runs_on_the_cpu() {
        assert_eq!(Backend::Auto.resolve().unwrap(), Backend::Cpu);
        let why = super::auto_fallback_reason().expect("Auto falls back here");
        assert!(why.contains("feature 'gpu' is off"), "{why}");
        // The hosts get the same text through the C ABI.
        let mut note: *const std::ffi::c_char = std::ptr::null();
        let status = crate::capi::isobar_auto_backend_note(&mut note);
        assert_eq!(status, crate::capi::IsobarStatus::Ok);
        // SAFETY: set by the call above, valid until the next isobar call on this thread.
        let note = unsafe { std::ffi::CStr::from_ptr(note) };
        assert_eq!(note.to_str().unwrap(), why);
        assert_no_gpu(Backend::Gpu.resolve().unwrap_err());
        assert_no_gpu(super::adapter_name().unwrap_err());

        // A 4×4×4 block of particles: a closed surface for both extractors.
        let positions: Vec<DVec3> = (0..64)
            .map(|i| DVec3::new((i % 4) as f64, (i / 4 % 4) as f64, (i / 16) as f64) * 0.5)
            .collect();
        let data = ParticleData {
            positions,
            ..ParticleData::default()
        };
        let settings = SphSettings {
            smoothing_length: SmoothingLength::Constant(0.5),
            ..SphSettings::default()
        };
        let field = SphField::new(&data, &settings).unwrap();

        let mc = |backend| correctors::Params {
            isovalues: vec![0.5],
            backend,
            ..correctors::Params::default()
        };
        let e = correctors::extract(&field, &data, &mc(Backend::Gpu), &mut Progress::none());
        assert_no_gpu(e.err().expect("a GPU extraction without the feature"));
        let auto =
            correctors::extract(&field, &data, &mc(Backend::Auto), &mut Progress::none()).unwrap();
        let cpu =
            correctors::extract(&field, &data, &mc(Backend::Cpu), &mut Progress::none()).unwrap();
        assert_eq!(auto.stats.backend, Backend::Cpu);
        assert!(!cpu.mesh.triangles.is_empty());
        assert_eq!(auto.mesh.triangles, cpu.mesh.triangles);
        assert_eq!(auto.mesh.positions, cpu.mesh.positions);

        let ad = |backend| adaptive::Params {
            isovalue: 0.5,
            backend,
            ..adaptive::Params::default()
        };
        let e = adaptive::extract_sph(&field, &ad(Backend::Gpu), &mut Progress::none());
        assert_no_gpu(e.err().expect("a GPU extraction without the feature"));
        let auto =
            adaptive::extract_sph(&field, &ad(Backend::Auto), &mut Progress::none()).unwrap();
        let cpu = adaptive::extract_sph(&field, &ad(Backend::Cpu), &mut Progress::none()).unwrap();
        assert!(!cpu.mesh.triangles.is_empty());
        assert_eq!(auto.mesh.triangles, cpu.mesh.triangles);
        assert_eq!(auto.mesh.positions, cpu.mesh.positions);
    }
}
