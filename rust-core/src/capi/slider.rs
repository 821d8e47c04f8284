//! The isovalue slider through the C ABI: build a store (from a volume file or a float
//! array), open it, set isovalues, read the core-owned arrays.
//!
//! A slider handle is mutable state: one thread at a time may use it. Arrays returned by
//! the accessors stay valid until the next `isobar_slider_set_isovalue` or
//! `isobar_slider_free` on that handle.

use super::{
    free_boxed, guard, invalid, non_null, opt_str, put, slice, with_progress, IsobarProgressFn,
    IsobarStatus,
};
use crate::field::grid::{Lattice, Values, Volume};
use crate::slider::{build_store, BuildParams, Change, Slider};
use glam::DVec3;
use std::ffi::{c_char, c_void};
use std::path::Path;

/// Opaque slider: a memory-mapped store and the surface at the current isovalue.
pub struct IsobarSlider {
    slider: Slider,
    change: Change,
    moved: Vec<u32>,
}

/// Summary of one isovalue change (`isobar_slider_set_isovalue`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct IsobarSliderChange {
    pub isovalue: f64,
    pub triangles_added: u64,
    pub triangles_removed: u64,
    pub vertices_moved: u64,
    pub edges_added: u64,
    pub edges_removed: u64,
    /// Wall time of the update, seconds.
    pub seconds: f64,
}

fn build_params(threshold: f64, max_levels: u32) -> BuildParams {
    let d = BuildParams::default();
    BuildParams {
        threshold: if threshold > 0.0 {
            threshold
        } else {
            d.threshold
        },
        max_levels: if max_levels > 0 {
            max_levels as usize
        } else {
            d.max_levels
        },
        ..d
    }
}

/// Builds the store of `volume` at `output` with the C progress callback.
fn build_to(
    volume: &Volume,
    output: &str,
    threshold: f64,
    max_levels: u32,
    progress: IsobarProgressFn,
    user: *mut c_void,
) -> crate::Result<()> {
    with_progress(progress, user, |p| {
        build_store(
            volume,
            Path::new(output),
            &build_params(threshold, max_levels),
            p,
        )
    })?;
    Ok(())
}

fn required(p: *const c_char, name: &'static str) -> crate::Result<String> {
    opt_str(p, name)?.ok_or_else(|| invalid(name, "must not be NULL"))
}

/// Builds a store at `store_path` from a volume file (.vti, .nrrd, .npy). `array` names
/// the ImageData point array (NULL: the default). `threshold` ≤ 0 and `max_levels` 0 take
/// the defaults. `progress` may be NULL.
#[no_mangle]
pub extern "C" fn isobar_slider_build_file(
    volume_path: *const c_char,
    array: *const c_char,
    store_path: *const c_char,
    threshold: f64,
    max_levels: u32,
    progress: IsobarProgressFn,
    user: *mut c_void,
) -> IsobarStatus {
    guard(|| {
        let input = required(volume_path, "volume_path")?;
        let output = required(store_path, "store_path")?;
        let array = opt_str(array, "array")?;
        let volume = crate::io::read_volume(Path::new(&input), array.as_deref(), None)?;
        build_to(&volume, &output, threshold, max_levels, progress, user)
    })
}

/// Builds a store from `dims[0]·dims[1]·dims[2]` f32 values, x fastest, with the given
/// origin and spacing (3 doubles each; NULL means 0 and 1).
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub extern "C" fn isobar_slider_build_f32(
    values: *const f32,
    dims: *const usize,
    origin: *const f64,
    spacing: *const f64,
    store_path: *const c_char,
    threshold: f64,
    max_levels: u32,
    progress: IsobarProgressFn,
    user: *mut c_void,
) -> IsobarStatus {
    guard(|| {
        let output = required(store_path, "store_path")?;
        let d = slice(dims, 3, "dims")?;
        let dims = [d[0], d[1], d[2]];
        let three = |p: *const f64, name, default: f64| -> crate::Result<DVec3> {
            if p.is_null() {
                Ok(DVec3::splat(default))
            } else {
                let s = slice(p, 3, name)?;
                Ok(DVec3::new(s[0], s[1], s[2]))
            }
        };
        let lattice = Lattice::new(
            dims,
            three(origin, "origin", 0.0)?,
            three(spacing, "spacing", 1.0)?,
        )?;
        let n = dims
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or_else(|| invalid("dims", "product overflows"))?;
        let values = slice(values, n, "values")?.to_vec();
        let volume = Volume::new(lattice, Values::F32(values))?;
        build_to(&volume, &output, threshold, max_levels, progress, user)
    })
}

/// Opens a store; on success `*out` owns a slider (free with `isobar_slider_free`) whose
/// surface is empty until the first `isobar_slider_set_isovalue`.
#[no_mangle]
pub extern "C" fn isobar_slider_open(
    store_path: *const c_char,
    out: *mut *mut IsobarSlider,
) -> IsobarStatus {
    guard(|| {
        let path = required(store_path, "store_path")?;
        if out.is_null() {
            return Err(invalid("out", "output pointer must not be NULL"));
        }
        let slider = Slider::open(Path::new(&path))?;
        let handle = Box::new(IsobarSlider {
            slider,
            change: Change::default(),
            moved: Vec::new(),
        });
        put(out, Box::into_raw(handle), "out")
    })
}

fn slider_mut<'a>(s: *mut IsobarSlider) -> crate::Result<&'a mut IsobarSlider> {
    // SAFETY: null or a live handle used by one thread at a time (documented).
    unsafe { s.as_mut() }.ok_or_else(|| invalid("slider", "must not be NULL"))
}

fn slider_ref<'a>(s: *const IsobarSlider) -> Option<&'a IsobarSlider> {
    // SAFETY: null or a live handle.
    unsafe { s.as_ref() }
}

/// Moves the surface to isovalue `iso`; `change` (may be NULL) receives the summary.
/// `progress` (may be NULL) is called during long walks.
#[no_mangle]
pub extern "C" fn isobar_slider_set_isovalue(
    s: *mut IsobarSlider,
    iso: f64,
    progress: IsobarProgressFn,
    user: *mut c_void,
    change: *mut IsobarSliderChange,
) -> IsobarStatus {
    guard(|| {
        let h = slider_mut(s)?;
        let c = with_progress(progress, user, |p| h.slider.set_isovalue_with(iso, p))?;
        h.moved.clear();
        h.moved
            .extend(c.moved_vertices.iter().flat_map(|&(a, b)| [a, b]));
        let summary = IsobarSliderChange {
            isovalue: c.isovalue,
            triangles_added: c.added_triangles.len() as u64,
            triangles_removed: c.removed_triangles.len() as u64,
            vertices_moved: c.moved_vertices.len() as u64,
            edges_added: c.edges_added,
            edges_removed: c.edges_removed,
            seconds: c.seconds,
        };
        h.change = c;
        if !change.is_null() {
            put(change, summary, "change")?;
        }
        Ok(())
    })
}

/// Number of vertices (0 for NULL).
#[no_mangle]
pub extern "C" fn isobar_slider_vertex_count(s: *const IsobarSlider) -> usize {
    slider_ref(s).map_or(0, |s| s.slider.vertex_count())
}

/// Number of triangles (0 for NULL).
#[no_mangle]
pub extern "C" fn isobar_slider_triangle_count(s: *const IsobarSlider) -> usize {
    slider_ref(s).map_or(0, |s| s.slider.triangle_count())
}

/// vertex_count × 3 f32 positions (V), or NULL.
#[no_mangle]
pub extern "C" fn isobar_slider_positions(s: *const IsobarSlider) -> *const f32 {
    slider_ref(s).map_or(std::ptr::null(), |s| s.slider.positions().as_ptr().cast())
}

/// vertex_count × 3 f32 unit normals (N), or NULL.
#[no_mangle]
pub extern "C" fn isobar_slider_normals(s: *const IsobarSlider) -> *const f32 {
    slider_ref(s).map_or(std::ptr::null(), |s| s.slider.normals().as_ptr().cast())
}

/// triangle_count × 3 u32 vertex indices (I), or NULL.
#[no_mangle]
pub extern "C" fn isobar_slider_triangles(s: *const IsobarSlider) -> *const u32 {
    slider_ref(s).map_or(std::ptr::null(), |s| {
        s.slider.triangle_array().as_ptr().cast()
    })
}

/// The last change's triangles: `which` 0 = added (new numbering), 1 = removed (old
/// numbering); `*count` receives the number of triangles (× 3 u32).
#[no_mangle]
pub extern "C" fn isobar_slider_change_triangles(
    s: *const IsobarSlider,
    which: u32,
    count: *mut usize,
    data: *mut *const u32,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "slider")?;
        let list = match which {
            0 => &s.change.added_triangles,
            1 => &s.change.removed_triangles,
            _ => {
                return Err(invalid(
                    "which",
                    format!("{which} is not 0 (added) or 1 (removed)"),
                ))
            }
        };
        put(count, list.len(), "count")?;
        put(data, list.as_ptr().cast(), "data")
    })
}

/// The last change's moved vertices as (before, after) u32 pairs; `*count` pairs.
#[no_mangle]
pub extern "C" fn isobar_slider_change_moved(
    s: *const IsobarSlider,
    count: *mut usize,
    data: *mut *const u32,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "slider")?;
        put(count, s.moved.len() / 2, "count")?;
        put(data, s.moved.as_ptr(), "data")
    })
}

/// Value range of the store's volume.
#[no_mangle]
pub extern "C" fn isobar_slider_value_range(
    s: *const IsobarSlider,
    min: *mut f64,
    max: *mut f64,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "slider")?;
        let (lo, hi) = s.slider.store().value_range();
        put(min, lo as f64, "min")?;
        put(max, hi as f64, "max")
    })
}

/// Updates applied so far and their total time in seconds.
#[no_mangle]
pub extern "C" fn isobar_slider_stats(
    s: *const IsobarSlider,
    updates: *mut u64,
    total_seconds: *mut f64,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "slider")?;
        let st = s.slider.stats();
        put(updates, st.updates, "updates")?;
        put(total_seconds, st.total_seconds, "total_seconds")
    })
}

/// Frees a slider and unmaps its store (NULL is ignored).
#[no_mangle]
pub extern "C" fn isobar_slider_free(s: *mut IsobarSlider) {
    free_boxed(s);
}
