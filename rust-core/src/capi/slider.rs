//! The isovalue slider through the C ABI: build a store (from a volume file or a float
//! array), open it, set isovalues, read the core-owned arrays.
//!
//! A slider handle is mutable state: one thread at a time may use it. Arrays returned by
//! the accessors stay valid until the next `isobar_slider_set_isovalue` or
//! `isobar_slider_free` on that handle; those of `isobar_slider_lod_mesh` also until the
//! next `isobar_slider_set_lod`.

use super::{
    free_boxed, guard, invalid, non_null, opt_str, put, set_last_warnings, slice, with_progress,
    IsobarProgressFn, IsobarStatus,
};
use crate::field::grid::{Lattice, Narrowing, Values, Volume};
use crate::slider::{build_store, BuildParams, Change, LodParams, Slider};
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

fn build_params(threshold: f64, max_levels: u32, memory_budget: u64) -> BuildParams {
    let d = BuildParams::default();
    BuildParams {
        memory_budget: if memory_budget > 0 {
            memory_budget
        } else {
            d.memory_budget
        },
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
    }
}

/// Builds the store of `volume` at `output` with the C progress callback.
fn build_to(
    volume: &Volume,
    output: &str,
    params: BuildParams,
    progress: IsobarProgressFn,
    user: *mut c_void,
) -> crate::Result<()> {
    with_progress(progress, user, |p| {
        build_store(volume, Path::new(output), &params, p)
    })?;
    set_last_warnings(&volume.warnings);
    Ok(())
}

fn required(p: *const c_char, name: &'static str) -> crate::Result<String> {
    opt_str(p, name)?.ok_or_else(|| invalid(name, "must not be NULL"))
}

/// Builds a store at `store_path` from a volume file (.vti, .nrrd, .npy). `array` names
/// the ImageData point array (NULL: the default). `threshold` ≤ 0, `max_levels` 0 and
/// `memory_budget` 0 (bytes the build may hold besides the volume; beyond about 29 a
/// node it sorts on disk, beside `store_path`) take the defaults. `progress` may be NULL.
#[no_mangle]
pub extern "C" fn isobar_slider_build_file(
    volume_path: *const c_char,
    array: *const c_char,
    store_path: *const c_char,
    threshold: f64,
    max_levels: u32,
    memory_budget: u64,
    progress: IsobarProgressFn,
    user: *mut c_void,
) -> IsobarStatus {
    set_last_warnings(&[]);
    guard(|| {
        let input = required(volume_path, "volume_path")?;
        let output = required(store_path, "store_path")?;
        let array = opt_str(array, "array")?;
        crate::slider::build::check_store_path(Path::new(&input), Path::new(&output))?;
        let volume = crate::io::read_volume(Path::new(&input), array.as_deref(), None)?;
        let params = build_params(threshold, max_levels, memory_budget);
        build_to(&volume, &output, params, progress, user)
    })
}

/// Builds a store from `dims[0]·dims[1]·dims[2]` f32 values, x fastest, with the given
/// origin and spacing (3 doubles each; NULL means 0 and 1); the other parameters as
/// [`isobar_slider_build_file`]'s.
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
    memory_budget: u64,
    progress: IsobarProgressFn,
    user: *mut c_void,
) -> IsobarStatus {
    let array = Array {
        dims,
        origin,
        spacing,
    };
    build_array(
        array,
        store_path,
        threshold,
        max_levels,
        memory_budget,
        progress,
        user,
        |lattice, n| Volume::new(lattice, Values::F32(slice(values, n, "values")?.to_vec())),
    )
}

/// [`isobar_slider_build_f32`] of f64 values, which the store holds as f32: a finite
/// value beyond f32's range is refused, and a value range f32 resolves coarsely (an
/// offset far from zero) is warned about (`isobar_last_warnings`).
#[no_mangle]
#[allow(clippy::too_many_arguments)]
pub extern "C" fn isobar_slider_build_f64(
    values: *const f64,
    dims: *const usize,
    origin: *const f64,
    spacing: *const f64,
    store_path: *const c_char,
    threshold: f64,
    max_levels: u32,
    memory_budget: u64,
    progress: IsobarProgressFn,
    user: *mut c_void,
) -> IsobarStatus {
    let array = Array {
        dims,
        origin,
        spacing,
    };
    build_array(
        array,
        store_path,
        threshold,
        max_levels,
        memory_budget,
        progress,
        user,
        |lattice, n| {
            let mut narrowing = Narrowing::default();
            let narrowed = slice(values, n, "values")?
                .iter()
                .map(|&v| narrowing.narrow(v))
                .collect();
            narrowing.finish(lattice, narrowed)
        },
    )
}

/// Where an array's nodes lie, as the `build_*` calls take it.
struct Array {
    dims: *const usize,
    origin: *const f64,
    spacing: *const f64,
}

/// The `build_*` calls of arrays: the lattice checked, then `volume(lattice, node count)`
/// (which reads the values) built into a store.
#[allow(clippy::too_many_arguments)]
fn build_array(
    array: Array,
    store_path: *const c_char,
    threshold: f64,
    max_levels: u32,
    memory_budget: u64,
    progress: IsobarProgressFn,
    user: *mut c_void,
    volume: impl FnOnce(Lattice, usize) -> crate::Result<Volume>,
) -> IsobarStatus {
    set_last_warnings(&[]);
    guard(|| {
        let output = required(store_path, "store_path")?;
        let d = slice(array.dims, 3, "dims")?;
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
            three(array.origin, "origin", 0.0)?,
            three(array.spacing, "spacing", 1.0)?,
        )?;
        let n = dims
            .iter()
            .try_fold(1usize, |a, &d| a.checked_mul(d))
            .ok_or_else(|| invalid("dims", "product overflows"))?;
        let volume = volume(lattice, n)?;
        let params = build_params(threshold, max_levels, memory_budget);
        build_to(&volume, &output, params, progress, user)
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

/// Sets the level of detail of `isobar_slider_lod_mesh`: `error_bound` is the largest
/// difference between a deleted sample and a merged cell's interpolant, as a fraction of
/// the value range in [0, 1) (0: off, the LOD mesh is the exact mesh; 0.001 is the paper's
/// bound); `max_level` is the most merge levels (a level-L cell spans 2^L lattice cells per
/// axis), 0 takes the default (3), at most 6. The exact arrays are unaffected. A new
/// setting invalidates the arrays of the last `isobar_slider_lod_mesh`.
#[no_mangle]
pub extern "C" fn isobar_slider_set_lod(
    s: *mut IsobarSlider,
    error_bound: f64,
    max_level: u32,
) -> IsobarStatus {
    guard(|| {
        let h = slider_mut(s)?;
        let d = LodParams::default();
        h.slider.set_lod(LodParams {
            error_bound,
            max_level: if max_level > 0 {
                max_level
            } else {
                d.max_level
            },
        })
    })
}

/// The level of detail set (`isobar_slider_set_lod`; a new slider has error bound 0).
#[no_mangle]
pub extern "C" fn isobar_slider_get_lod(
    s: *const IsobarSlider,
    error_bound: *mut f64,
    max_level: *mut u32,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "slider")?;
        let lod = s.slider.lod();
        put(error_bound, lod.error_bound, "error_bound")?;
        put(max_level, lod.max_level, "max_level")
    })
}

/// The level-of-detail mesh of the current surface at the bound of
/// `isobar_slider_set_lod`, computed on the first call after an isovalue or LOD change
/// (O(surface)). Closed surfaces stay watertight and oriented like the exact mesh; every
/// vertex lies on the exact surface. At bound 0 it is the exact mesh, its vertices in
/// another order. `*vertex_count` and `*triangle_count` receive the counts,
/// `*positions` and `*normals` vertex_count × 3 f32, `*triangles` triangle_count × 3 u32.
#[no_mangle]
pub extern "C" fn isobar_slider_lod_mesh(
    s: *const IsobarSlider,
    vertex_count: *mut usize,
    triangle_count: *mut usize,
    positions: *mut *const f32,
    normals: *mut *const f32,
    triangles: *mut *const u32,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "slider")?;
        for (p, name) in [
            (vertex_count.is_null(), "vertex_count"),
            (triangle_count.is_null(), "triangle_count"),
            (positions.is_null(), "positions"),
            (normals.is_null(), "normals"),
            (triangles.is_null(), "triangles"),
        ] {
            if p {
                return Err(invalid(name, "output pointer must not be NULL"));
            }
        }
        let m = s.slider.lod_mesh()?;
        put(vertex_count, m.positions.len(), "vertex_count")?;
        put(triangle_count, m.triangles.len(), "triangle_count")?;
        put(positions, m.positions.as_ptr().cast(), "positions")?;
        put(normals, m.normals.as_ptr().cast(), "normals")?;
        put(triangles, m.triangles.as_ptr().cast(), "triangles")
    })
}

/// Frees a slider and unmaps its store (NULL is ignored).
#[no_mangle]
pub extern "C" fn isobar_slider_free(s: *mut IsobarSlider) {
    free_boxed(s);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::mesh::Mesh;

    /// Minus the distance to a point off the lattice: closed spheres for isovalues −r.
    fn sphere(n: usize) -> Vec<f32> {
        let c = [
            n as f64 / 2.0 + 0.3,
            n as f64 / 2.0 + 0.17,
            n as f64 / 2.0 - 0.21,
        ];
        let mut v = Vec::with_capacity(n * n * n);
        for z in 0..n {
            for y in 0..n {
                for x in 0..n {
                    let d = [x as f64 - c[0], y as f64 - c[1], z as f64 - c[2]];
                    v.push(-(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt() as f32);
                }
            }
        }
        v
    }

    fn open_sphere(n: usize, name: &str) -> *mut IsobarSlider {
        let dir = std::env::temp_dir().join(format!("isobar-capi-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = std::ffi::CString::new(dir.join(name).to_str().unwrap()).unwrap();
        let values = sphere(n);
        let dims = [n; 3];
        let status = isobar_slider_build_f32(
            values.as_ptr(),
            dims.as_ptr(),
            std::ptr::null(),
            std::ptr::null(),
            path.as_ptr(),
            0.0,
            0,
            0,
            None,
            std::ptr::null_mut(),
        );
        assert_eq!(status, IsobarStatus::Ok);
        let mut s = std::ptr::null_mut();
        assert_eq!(isobar_slider_open(path.as_ptr(), &mut s), IsobarStatus::Ok);
        s
    }

    /// Positions, normals and triangles.
    type Arrays = (Vec<[f32; 3]>, Vec<[f32; 3]>, Vec<[u32; 3]>);

    /// Positions, normals and triangles of the LOD mesh, copied out of the C arrays.
    fn lod_arrays(s: *const IsobarSlider) -> Arrays {
        let (mut nv, mut nt) = (0usize, 0usize);
        let (mut p, mut n, mut t) = (std::ptr::null(), std::ptr::null(), std::ptr::null());
        let status = isobar_slider_lod_mesh(s, &mut nv, &mut nt, &mut p, &mut n, &mut t);
        assert_eq!(status, IsobarStatus::Ok);
        // SAFETY: the arrays the call documents, alive until the next update.
        unsafe {
            (
                std::slice::from_raw_parts(p.cast::<[f32; 3]>(), nv).to_vec(),
                std::slice::from_raw_parts(n.cast::<[f32; 3]>(), nv).to_vec(),
                std::slice::from_raw_parts(t.cast::<[u32; 3]>(), nt).to_vec(),
            )
        }
    }

    /// The exact arrays through the C accessors.
    fn exact_arrays(s: *const IsobarSlider) -> Arrays {
        let nv = isobar_slider_vertex_count(s);
        let nt = isobar_slider_triangle_count(s);
        // SAFETY: as above.
        unsafe {
            (
                std::slice::from_raw_parts(isobar_slider_positions(s).cast::<[f32; 3]>(), nv)
                    .to_vec(),
                std::slice::from_raw_parts(isobar_slider_normals(s).cast::<[f32; 3]>(), nv)
                    .to_vec(),
                std::slice::from_raw_parts(isobar_slider_triangles(s).cast::<[u32; 3]>(), nt)
                    .to_vec(),
            )
        }
    }

    /// Triangles as position triples, rotated to start at the smallest (orientation
    /// kept), sorted: equal for two numberings of one mesh.
    fn canon(pos: &[[f32; 3]], tris: &[[u32; 3]]) -> Vec<[[u32; 3]; 3]> {
        let key = |i: u32| pos[i as usize].map(f32::to_bits);
        let mut out: Vec<[[u32; 3]; 3]> = tris
            .iter()
            .map(|t| {
                let k = t.map(key);
                let r = (0..3).min_by_key(|&i| k[i]).unwrap();
                [k[r], k[(r + 1) % 3], k[(r + 2) % 3]]
            })
            .collect();
        out.sort_unstable();
        out
    }

    fn watertight(pos: &[[f32; 3]], tris: &[[u32; 3]]) -> bool {
        Mesh {
            positions: pos.iter().map(|p| p.map(f64::from)).collect(),
            triangles: tris.to_vec(),
            ..Mesh::default()
        }
        .topology()
        .is_watertight_oriented()
    }

    #[test]
    fn lod_mesh_through_the_c_abi() {
        let s = open_sphere(48, "lod.isoslider");
        let (mut bound, mut levels) = (1.0, 99);
        assert_eq!(
            isobar_slider_get_lod(s, &mut bound, &mut levels),
            IsobarStatus::Ok
        );
        assert_eq!((bound, levels), (0.0, 3), "a new slider has LOD off");
        assert_eq!(
            isobar_slider_set_isovalue(s, -19.0, None, std::ptr::null_mut(), std::ptr::null_mut()),
            IsobarStatus::Ok
        );
        let (pos, nor, tris) = exact_arrays(s);
        assert!(tris.len() > 1000);

        // Bound 0: the exact mesh, in another vertex order.
        let (lp, ln, lt) = lod_arrays(s);
        assert_eq!(lt.len(), tris.len());
        assert_eq!(canon(&lp, &lt), canon(&pos, &tris));
        let mut a: Vec<_> = pos
            .iter()
            .zip(&nor)
            .map(|(p, n)| (p.map(f32::to_bits), n.map(f32::to_bits)))
            .collect();
        let mut b: Vec<_> = lp
            .iter()
            .zip(&ln)
            .map(|(p, n)| (p.map(f32::to_bits), n.map(f32::to_bits)))
            .collect();
        a.sort_unstable();
        b.sort_unstable();
        assert_eq!(a, b, "same vertices with the same normals");

        // A loose bound: fewer triangles, still closed and oriented, unit normals.
        assert_eq!(isobar_slider_set_lod(s, 0.01, 0), IsobarStatus::Ok);
        assert_eq!(
            isobar_slider_get_lod(s, &mut bound, &mut levels),
            IsobarStatus::Ok
        );
        assert_eq!((bound, levels), (0.01, 3));
        let (lp, ln, lt) = lod_arrays(s);
        assert!(
            (lt.len() as f64) < 0.6 * tris.len() as f64,
            "{} LOD triangles for {} exact",
            lt.len(),
            tris.len()
        );
        assert!(watertight(&lp, &lt));
        assert!(ln
            .iter()
            .all(|n| ((n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt() - 1.0).abs() < 1e-4));
        // Equal to the Rust API's mesh.
        // SAFETY: a live handle.
        let rust = unsafe { &*s }.slider.lod_mesh().unwrap();
        assert_eq!((rust.positions.clone(), rust.triangles.clone()), (lp, lt));

        // The setting survives isovalue updates; the exact arrays do not change with it.
        assert_eq!(
            isobar_slider_set_isovalue(s, -15.0, None, std::ptr::null_mut(), std::ptr::null_mut()),
            IsobarStatus::Ok
        );
        let (_, _, t15) = exact_arrays(s);
        let (lp, _, lt) = lod_arrays(s);
        assert!(lt.len() < t15.len() && watertight(&lp, &lt));
        assert_eq!(isobar_slider_set_lod(s, 0.0, 0), IsobarStatus::Ok);
        let (lp, _, lt) = lod_arrays(s);
        let (pos, _, tris) = exact_arrays(s);
        assert_eq!(canon(&lp, &lt), canon(&pos, &tris));

        // Refusals: bad bounds and levels, NULL handle and outputs; the setting stays.
        for (b, l) in [(-0.1, 0), (1.0, 0), (f64::NAN, 0), (0.01, 7)] {
            assert_eq!(
                isobar_slider_set_lod(s, b, l),
                IsobarStatus::ErrInvalidArgument
            );
        }
        assert_eq!(
            isobar_slider_set_lod(std::ptr::null_mut(), 0.01, 0),
            IsobarStatus::ErrInvalidArgument
        );
        assert_eq!(
            isobar_slider_get_lod(s, &mut bound, &mut levels),
            IsobarStatus::Ok
        );
        assert_eq!(bound, 0.0);
        let (mut nv, mut nt) = (0usize, 0usize);
        let (mut p, mut n, mut t) = (std::ptr::null(), std::ptr::null(), std::ptr::null());
        assert_eq!(
            isobar_slider_lod_mesh(std::ptr::null(), &mut nv, &mut nt, &mut p, &mut n, &mut t),
            IsobarStatus::ErrInvalidArgument
        );
        assert_eq!(
            isobar_slider_lod_mesh(s, &mut nv, &mut nt, &mut p, std::ptr::null_mut(), &mut t),
            IsobarStatus::ErrInvalidArgument
        );
        assert_eq!(
            isobar_slider_get_lod(s, std::ptr::null_mut(), &mut levels),
            IsobarStatus::ErrInvalidArgument
        );
        isobar_slider_free(s);
    }
}
