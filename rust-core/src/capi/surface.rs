//! Extraction results: core-owned arrays, valid until `isobar_surface_free`.

use super::{
    attribute_out, copy_versioned_out, free_boxed, guard, invalid, names_of, non_null, opt_str,
    IsobarStatus,
};
use crate::correctors::Extraction;
use std::ffi::{c_char, CString};

/// Opaque extraction result.
pub struct IsobarSurface {
    extraction: Extraction,
    names: Vec<CString>,
    /// The extraction's warnings, one a line.
    warnings: CString,
}

impl IsobarSurface {
    pub(crate) fn new(extraction: Extraction) -> Box<Self> {
        let names = names_of(&extraction.mesh.attributes);
        let warnings = super::warning_lines(&extraction.stats.warnings);
        Box::new(IsobarSurface {
            extraction,
            names,
            warnings,
        })
    }
}

/// Statistics of an extraction (the paper's Tables I–V). Set `struct_size` before
/// calling `isobar_surface_stats`; fields beyond it are not written.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct IsobarStats {
    pub struct_size: u32,
    pub virtual_cells: u64,
    pub seed_cells: u64,
    pub non_intersected_seeds: u64,
    pub discarded_cells: u64,
    pub cells_used: u64,
    pub vertices: u64,
    pub triangles: u64,
    pub field_evaluations: u64,
    pub node_evaluations: u64,
    pub cache_hit_ratio: f64,
    pub correction_mean: f64,
    pub correction_max: f64,
    pub correction_stdev: f64,
    pub unconverged_vertices: u64,
    pub trim_cut_points: u64,
    pub seconds_seeds: f64,
    pub seconds_tracking: f64,
    pub seconds_vertices: f64,
    pub seconds_trimming: f64,
    pub seconds_attributes: f64,
    pub seconds_total: f64,
    /// The back end that ran (`ISOBAR_BACKEND_CPU` or `ISOBAR_BACKEND_GPU`): for Marching
    /// Correctors the seed cells' neighbour search. Added in version 2.
    pub backend: u32,
}

fn surface<'a>(s: *const IsobarSurface) -> Option<&'a IsobarSurface> {
    // SAFETY: null or a live handle.
    unsafe { s.as_ref() }
}

/// Number of vertices (0 for NULL).
#[no_mangle]
pub extern "C" fn isobar_surface_vertex_count(s: *const IsobarSurface) -> usize {
    surface(s).map_or(0, |s| s.extraction.mesh.positions.len())
}

/// Number of triangles (0 for NULL).
#[no_mangle]
pub extern "C" fn isobar_surface_triangle_count(s: *const IsobarSurface) -> usize {
    surface(s).map_or(0, |s| s.extraction.mesh.triangles.len())
}

/// vertex_count × 3 f64 positions, or NULL.
#[no_mangle]
pub extern "C" fn isobar_surface_positions(s: *const IsobarSurface) -> *const f64 {
    surface(s).map_or(std::ptr::null(), |s| {
        s.extraction.mesh.positions.as_ptr().cast()
    })
}

/// vertex_count × 3 f32 unit normals, or NULL when normals were not computed.
#[no_mangle]
pub extern "C" fn isobar_surface_normals(s: *const IsobarSurface) -> *const f32 {
    match surface(s) {
        Some(s) if !s.extraction.mesh.normals.is_empty() => {
            s.extraction.mesh.normals.as_ptr().cast()
        }
        _ => std::ptr::null(),
    }
}

/// triangle_count × 3 u32 vertex indices (counter-clockwise seen from where the normals
/// point), or NULL.
#[no_mangle]
pub extern "C" fn isobar_surface_triangles(s: *const IsobarSurface) -> *const u32 {
    surface(s).map_or(std::ptr::null(), |s| {
        s.extraction.mesh.triangles.as_ptr().cast()
    })
}

/// Number of per-vertex arrays (SumOfWeights, requested attributes, Isovalue).
#[no_mangle]
pub extern "C" fn isobar_surface_attribute_count(s: *const IsobarSurface) -> usize {
    surface(s).map_or(0, |s| s.extraction.mesh.attributes.len())
}

/// Name, components and data (vertex_count × components f64) of array `index`.
#[no_mangle]
pub extern "C" fn isobar_surface_attribute(
    s: *const IsobarSurface,
    index: usize,
    name: *mut *const c_char,
    components: *mut usize,
    data: *mut *const f64,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "surface")?;
        attribute_out(
            &s.extraction.mesh.attributes,
            &s.names,
            index,
            name,
            components,
            data,
        )
    })
}

/// What the extraction warns about although it succeeded, one warning a line: a kernel
/// wider than the whole particle set (h and positions in different units?), an isovalue
/// the field never crosses. "" when there is nothing to say, and for NULL. Hosts show
/// each line as a warning. Valid until `isobar_surface_free`.
#[no_mangle]
pub extern "C" fn isobar_surface_warnings(s: *const IsobarSurface) -> *const c_char {
    surface(s).map_or(c"".as_ptr(), |s| s.warnings.as_ptr())
}

/// Copies the statistics into `out` (whose `struct_size` the caller sets).
#[no_mangle]
pub extern "C" fn isobar_surface_stats(
    s: *const IsobarSurface,
    out: *mut IsobarStats,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "surface")?;
        let st = &s.extraction.stats;
        let t = &st.timings;
        let full = IsobarStats {
            struct_size: 0,
            virtual_cells: st.virtual_cells,
            seed_cells: st.seed_cells,
            non_intersected_seeds: st.non_intersected_seeds,
            discarded_cells: st.discarded_cells,
            cells_used: st.cells_used,
            vertices: st.vertices,
            triangles: st.triangles,
            field_evaluations: st.field_evaluations,
            node_evaluations: st.node_evaluations,
            cache_hit_ratio: st.cache_hit_ratio,
            correction_mean: st.correction_mean,
            correction_max: st.correction_max,
            correction_stdev: st.correction_stdev,
            unconverged_vertices: st.unconverged_vertices,
            trim_cut_points: st.trim_cut_points,
            seconds_seeds: t.seeds,
            seconds_tracking: t.tracking,
            seconds_vertices: t.vertices,
            seconds_trimming: t.trimming,
            seconds_attributes: t.attributes,
            seconds_total: t.total,
            backend: super::adaptive::backend_to_c(st.backend),
        };
        copy_versioned_out(full, out, "out")
    })
}

/// Writes the surface to a .ply, .obj or .vtp file (through a temporary file).
#[no_mangle]
pub extern "C" fn isobar_surface_write(
    s: *const IsobarSurface,
    path: *const c_char,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "surface")?;
        let path = opt_str(path, "path")?.ok_or_else(|| invalid("path", "must not be NULL"))?;
        crate::io::write_mesh(std::path::Path::new(&path), &s.extraction.mesh)
    })
}

/// Frees a surface (NULL is ignored).
#[no_mangle]
pub extern "C" fn isobar_surface_free(s: *mut IsobarSurface) {
    free_boxed(s);
}
