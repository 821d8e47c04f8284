//! Particle handles: built from caller arrays or read from a file.

use super::{
    add_array, free_boxed, guard, invalid, names_of, non_null, opt_str, put, slice, IsobarStatus,
};
use crate::field::particles::ParticleData;
use glam::DVec3;
use std::ffi::{c_char, CString};

/// Opaque particle set.
pub struct IsobarParticles {
    pub(crate) data: ParticleData,
    /// NUL-terminated copies of the array names, for `isobar_particles_array_info`.
    names: Vec<CString>,
}

impl IsobarParticles {
    fn new(data: ParticleData) -> Box<Self> {
        let names = names_of(&data.attributes);
        Box::new(IsobarParticles { data, names })
    }
}

/// Copies `count` xyz triples of any float type into a new particle handle.
fn create<T: Copy + Into<f64>>(
    positions: *const T,
    count: usize,
    out: *mut *mut IsobarParticles,
) -> Result<(), crate::Error> {
    let len = count
        .checked_mul(3)
        .ok_or_else(|| invalid("count", "too large"))?;
    let xyz = slice(positions, len, "positions")?;
    let positions = xyz
        .chunks_exact(3)
        .map(|c| DVec3::new(c[0].into(), c[1].into(), c[2].into()))
        .collect();
    let data = ParticleData {
        positions,
        attributes: vec![],
        ..Default::default()
    };
    put(out, Box::into_raw(IsobarParticles::new(data)), "out")
}

/// Creates a particle set from `count` xyz triples of f64 (copied). NaN or infinite
/// coordinates are reported when a field is built, naming the particle.
#[no_mangle]
pub extern "C" fn isobar_particles_create(
    positions: *const f64,
    count: usize,
    out: *mut *mut IsobarParticles,
) -> IsobarStatus {
    guard(|| create(positions, count, out))
}

/// As `isobar_particles_create`, from f32 triples.
#[no_mangle]
pub extern "C" fn isobar_particles_create_f32(
    positions: *const f32,
    count: usize,
    out: *mut *mut IsobarParticles,
) -> IsobarStatus {
    guard(|| create(positions, count, out))
}

fn add(
    particles: *mut IsobarParticles,
    name: *const c_char,
    count: usize,
    components: usize,
    read: impl FnOnce(usize) -> Result<Vec<f64>, crate::Error>,
) -> Result<(), crate::Error> {
    // SAFETY: the caller promises a live handle not used by another thread meanwhile.
    let p =
        unsafe { particles.as_mut() }.ok_or_else(|| invalid("particles", "must not be NULL"))?;
    let items = p.data.len();
    add_array(
        &mut p.data.attributes,
        items,
        "particles",
        name,
        count,
        components,
        read,
    )?;
    p.names = names_of(&p.data.attributes);
    Ok(())
}

/// Adds (or replaces) a per-particle array of `count` items × `components` f64 values,
/// item-major. `count` must equal the number of particles.
#[no_mangle]
pub extern "C" fn isobar_particles_add_array(
    particles: *mut IsobarParticles,
    name: *const c_char,
    data: *const f64,
    count: usize,
    components: usize,
) -> IsobarStatus {
    guard(|| {
        add(particles, name, count, components, |len| {
            Ok(slice(data, len, "data")?.to_vec())
        })
    })
}

/// As `isobar_particles_add_array`, from f32 values.
#[no_mangle]
pub extern "C" fn isobar_particles_add_array_f32(
    particles: *mut IsobarParticles,
    name: *const c_char,
    data: *const f32,
    count: usize,
    components: usize,
) -> IsobarStatus {
    guard(|| {
        add(particles, name, count, components, |len| {
            Ok(slice(data, len, "data")?
                .iter()
                .map(|&v| v as f64)
                .collect())
        })
    })
}

/// Reads a particle file (any format the CLI reads).
#[no_mangle]
pub extern "C" fn isobar_particles_read(
    path: *const c_char,
    out: *mut *mut IsobarParticles,
) -> IsobarStatus {
    guard(|| {
        let path = opt_str(path, "path")?.ok_or_else(|| invalid("path", "must not be NULL"))?;
        let data = crate::io::read_particles(std::path::Path::new(&path))?;
        put(out, Box::into_raw(IsobarParticles::new(data)), "out")
    })
}

/// Number of particles (0 for NULL).
#[no_mangle]
pub extern "C" fn isobar_particles_count(particles: *const IsobarParticles) -> usize {
    // SAFETY: null or a live handle.
    unsafe { particles.as_ref() }.map_or(0, |p| p.data.len())
}

/// Number of named arrays (0 for NULL).
#[no_mangle]
pub extern "C" fn isobar_particles_array_count(particles: *const IsobarParticles) -> usize {
    // SAFETY: null or a live handle.
    unsafe { particles.as_ref() }.map_or(0, |p| p.data.attributes.len())
}

/// Name (valid while the handle lives and no array is added) and component count of
/// array `index`.
#[no_mangle]
pub extern "C" fn isobar_particles_array_info(
    particles: *const IsobarParticles,
    index: usize,
    name: *mut *const c_char,
    components: *mut usize,
) -> IsobarStatus {
    guard(|| {
        let p = non_null(particles, "particles")?;
        let a = p.data.attributes.get(index).ok_or_else(|| {
            invalid(
                "index",
                format!(
                    "{index} is out of range ({} arrays)",
                    p.data.attributes.len()
                ),
            )
        })?;
        put(name, p.names[index].as_ptr(), "name")?;
        put(components, a.components, "components")
    })
}

/// Copies the positions (count × 3 f64) into `out` of `len` values.
#[no_mangle]
pub extern "C" fn isobar_particles_copy_positions(
    particles: *const IsobarParticles,
    out: *mut f64,
    len: usize,
) -> IsobarStatus {
    guard(|| {
        let p = non_null(particles, "particles")?;
        let dst = writable(out, len, p.data.len() * 3)?;
        for (d, x) in dst.chunks_exact_mut(3).zip(&p.data.positions) {
            d.copy_from_slice(&x.to_array());
        }
        Ok(())
    })
}

/// Copies array `name` (count × components f64) into `out` of `len` values.
#[no_mangle]
pub extern "C" fn isobar_particles_copy_array(
    particles: *const IsobarParticles,
    name: *const c_char,
    out: *mut f64,
    len: usize,
) -> IsobarStatus {
    guard(|| {
        let p = non_null(particles, "particles")?;
        let name = opt_str(name, "name")?.ok_or_else(|| invalid("name", "must not be NULL"))?;
        let a = p.data.require(&name)?;
        writable(out, len, a.data.len())?.copy_from_slice(&a.data);
        Ok(())
    })
}

/// Frees a particle set (NULL is ignored).
#[no_mangle]
pub extern "C" fn isobar_particles_free(particles: *mut IsobarParticles) {
    free_boxed(particles);
}

/// A caller buffer of exactly `needed` values.
pub(crate) fn writable<'a, T>(
    out: *mut T,
    len: usize,
    needed: usize,
) -> Result<&'a mut [T], crate::Error> {
    if len != needed {
        return Err(invalid(
            "len",
            format!("the buffer holds {len} values, {needed} are needed"),
        ));
    }
    if needed == 0 {
        return Ok(&mut []);
    }
    if out.is_null() {
        return Err(invalid("out", "must not be NULL"));
    }
    // SAFETY: non-null, the caller promises `len` writable values.
    Ok(unsafe { std::slice::from_raw_parts_mut(out, len) })
}
