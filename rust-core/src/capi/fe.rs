//! High-order finite elements through the C ABI: a mesh of Lagrange cells (from a file or
//! from VTK-style arrays, as a host holds them), sampled by the particle system into
//! oriented point samples.

use super::sph::IsobarProgressFn;
use super::{
    add_array, attribute_out, copy_versioned_out, free_boxed, guard, invalid, names_of, non_null,
    opt_str, put, slice, with_progress, IsobarStatus,
};
use crate::field::fe::FeMesh;
use crate::highorder::{self, Params, Stats};
use crate::samples::PointSamples;
use glam::DVec3;
use std::ffi::{c_char, c_void, CString};

/// Opaque mesh of Lagrange cells with per-point arrays.
pub struct IsobarFeMesh {
    mesh: FeMesh,
    /// NUL-terminated copies of the point arrays' names, for `isobar_fe_mesh_array`.
    names: Vec<CString>,
}

impl IsobarFeMesh {
    fn new(mesh: FeMesh) -> *mut IsobarFeMesh {
        let names = names_of(&mesh.point_data);
        Box::into_raw(Box::new(IsobarFeMesh { mesh, names }))
    }
}

/// Opaque point samples of an isosurface: positions, normals, radii and named arrays;
/// arrays stay valid until `isobar_samples_free`.
pub struct IsobarSamples {
    samples: PointSamples,
    stats: Stats,
    names: Vec<CString>,
    /// The run's warnings, one a line.
    warnings: CString,
}

/// Options of the particle system (the paper's s, ρ, ε_T ...). Fill with
/// `isobar_fe_params_default`, then change fields; `struct_size` lets later versions add
/// fields at the end.
#[repr(C)]
#[derive(Clone, Copy, Debug)]
pub struct IsobarFeParams {
    pub struct_size: u32,
    /// Coarse-to-fine levels above the final spacing (each halves s; at most 8): at least
    /// this many, more while the seeds lie sparser than the coarsest spacing.
    pub levels: u32,
    /// The isovalue C.
    pub iso: f64,
    /// s: particle spacing on flat parts, world units; 0 picks 1/40 of the bounding-box
    /// diagonal.
    pub spacing: f64,
    /// ρ: extra density on curved parts (0: uniform spacing).
    pub rho: f64,
    /// ε_T: every sample has |F - C| at most this.
    pub tolerance: f64,
    /// Upper bound of the curvature scaling, as a multiple of the flat density.
    pub max_density: f64,
    /// Steady state: relative change of the system energy below this.
    pub steady_fraction: f64,
    /// Most sweeps per relaxation.
    pub max_iterations: u32,
    /// Neighbour lists are rebuilt every this many sweeps.
    pub neighbour_refresh: u32,
    /// Most split/delete rounds at the final spacing.
    pub split_rounds: u32,
    pub _reserved: u32,
    /// Seed of the random bias of split/delete decisions.
    pub seed: u64,
}

/// Size of the first version of `IsobarFeParams`.
const FE_PARAMS_V1_SIZE: usize = 80;

impl Default for IsobarFeParams {
    fn default() -> Self {
        let p = Params::default();
        IsobarFeParams {
            struct_size: std::mem::size_of::<IsobarFeParams>() as u32,
            levels: p.levels as u32,
            iso: p.iso,
            spacing: p.spacing,
            rho: p.rho,
            tolerance: p.tolerance,
            max_density: p.max_density,
            steady_fraction: p.steady_fraction,
            max_iterations: p.max_iterations as u32,
            neighbour_refresh: p.neighbour_refresh as u32,
            split_rounds: p.split_rounds as u32,
            _reserved: 0,
            seed: p.seed,
        }
    }
}

impl From<&IsobarFeParams> for Params {
    fn from(p: &IsobarFeParams) -> Params {
        Params {
            iso: p.iso,
            spacing: p.spacing,
            rho: p.rho,
            tolerance: p.tolerance,
            max_density: p.max_density,
            levels: p.levels as usize,
            max_iterations: p.max_iterations as usize,
            steady_fraction: p.steady_fraction,
            neighbour_refresh: p.neighbour_refresh as usize,
            split_rounds: p.split_rounds as usize,
            seed: p.seed,
        }
    }
}

/// What a sampling run did. Set `struct_size` before `isobar_samples_stats`; fields beyond
/// it are not written.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default)]
pub struct IsobarFeStats {
    pub struct_size: u32,
    pub particles: u64,
    /// Projected seeds before thinning.
    pub seeds: u64,
    /// Relaxation sweeps over all levels.
    pub iterations: u64,
    /// Forward evaluations (basis, mapping and field at one reference point).
    pub evaluations: u64,
    pub splits: u64,
    pub deletes: u64,
    /// The spacing s used.
    pub spacing: f64,
    /// Largest |F - C| over the samples.
    pub max_residual: f64,
}

/// Fills `out` with the core's default particle-system options.
#[no_mangle]
pub extern "C" fn isobar_fe_params_default(out: *mut IsobarFeParams) -> IsobarStatus {
    guard(|| put(out, IsobarFeParams::default(), "out"))
}

/// Builds a mesh from VTK-style arrays (copied): `point_count` xyz f64 triples; per cell a
/// VTK type (71 Lagrange tetrahedron, 72 hexahedron, 73 wedge, or a linear or quadratic
/// cell: 10 tetra, 11 voxel, 12 hexahedron, 13 wedge, 24 quadratic tetra, 25 quadratic
/// hexahedron, 26 quadratic wedge, 29 triquadratic hexahedron, 31 quadratic-linear wedge,
/// 32 biquadratic-quadratic wedge, read as the Lagrange cell of the same functions);
/// `offsets` (cell_count + 1
/// entries, cell c's nodes are `connectivity[offsets[c]..offsets[c+1]]`, in VTK's node
/// order); `degrees` is NULL or cell_count × 3 orders (VTK's HigherOrderDegrees). Elements
/// that are inverted or degenerate are refused, naming the cell.
#[no_mangle]
pub extern "C" fn isobar_fe_mesh_create(
    points: *const f64,
    point_count: usize,
    types: *const u8,
    cell_count: usize,
    offsets: *const i64,
    connectivity: *const i64,
    connectivity_len: usize,
    degrees: *const u32,
    out: *mut *mut IsobarFeMesh,
) -> IsobarStatus {
    guard(|| {
        if out.is_null() {
            return Err(invalid("out", "output pointer must not be NULL"));
        }
        let len = point_count
            .checked_mul(3)
            .ok_or_else(|| invalid("point_count", "too large"))?;
        let points: Vec<DVec3> = slice(points, len, "points")?
            .chunks_exact(3)
            .map(|c| DVec3::new(c[0], c[1], c[2]))
            .collect();
        let types = slice(types, cell_count, "types")?;
        let offsets = slice(offsets, cell_count + 1, "offsets")?
            .iter()
            .enumerate()
            .map(|(i, &o)| {
                usize::try_from(o).map_err(|_| invalid("offsets", format!("entry {i} is {o}")))
            })
            .collect::<Result<Vec<usize>, _>>()?;
        let connectivity = slice(connectivity, connectivity_len, "connectivity")?
            .iter()
            .enumerate()
            .map(|(i, &n)| {
                u32::try_from(n).map_err(|_| {
                    invalid(
                        "connectivity",
                        format!("entry {i} is {n}, not a point index"),
                    )
                })
            })
            .collect::<Result<Vec<u32>, _>>()?;
        let degrees = if degrees.is_null() {
            None
        } else {
            let d = slice(degrees, cell_count * 3, "degrees")?;
            Some(
                d.chunks_exact(3)
                    .map(|c| [c[0] as usize, c[1] as usize, c[2] as usize])
                    .collect::<Vec<_>>(),
            )
        };
        let mesh = FeMesh::new(
            "mesh",
            points,
            types,
            &offsets,
            connectivity,
            degrees.as_deref(),
            Vec::new(),
        )?;
        put(out, IsobarFeMesh::new(mesh), "out")
    })
}

/// Reads a mesh with its point arrays from a file (.vtu with Lagrange cells, or Gmsh .msh
/// v4.1 with high-order elements and $NodeData).
#[no_mangle]
pub extern "C" fn isobar_fe_mesh_read(
    path: *const c_char,
    out: *mut *mut IsobarFeMesh,
) -> IsobarStatus {
    guard(|| {
        let path = opt_str(path, "path")?.ok_or_else(|| invalid("path", "must not be NULL"))?;
        if out.is_null() {
            return Err(invalid("out", "output pointer must not be NULL"));
        }
        let mesh = crate::io::read_fe_mesh(std::path::Path::new(&path))?;
        put(out, IsobarFeMesh::new(mesh), "out")
    })
}

/// Adds (or replaces) a per-point array: `count` items × `components` f64, item-major;
/// `count` must equal the number of points.
#[no_mangle]
pub extern "C" fn isobar_fe_mesh_add_array(
    mesh: *mut IsobarFeMesh,
    name: *const c_char,
    data: *const f64,
    count: usize,
    components: usize,
) -> IsobarStatus {
    guard(|| {
        // SAFETY: the caller promises a live handle not used by another thread meanwhile.
        let m = unsafe { mesh.as_mut() }.ok_or_else(|| invalid("mesh", "must not be NULL"))?;
        // Checked and read as every host array is, then completed by the mesh over the
        // points it made for serendipity cells.
        let mut read = Vec::new();
        add_array(
            &mut read,
            m.mesh.given_points(),
            "points",
            name,
            count,
            components,
            |len| Ok(slice(data, len, "data")?.to_vec()),
        )?;
        m.mesh
            .add_point_array(read.pop().expect("add_array adds one array"))?;
        m.names = names_of(&m.mesh.point_data);
        Ok(())
    })
}

/// Number of per-point arrays of a mesh (0 for NULL).
#[no_mangle]
pub extern "C" fn isobar_fe_mesh_array_count(mesh: *const IsobarFeMesh) -> usize {
    // SAFETY: null or a live handle.
    unsafe { mesh.as_ref() }.map_or(0, |m| m.mesh.point_data.len())
}

/// Name, components and data (point_count × components f64) of point array `index`; valid
/// until the mesh is freed or an array is added.
#[no_mangle]
pub extern "C" fn isobar_fe_mesh_array(
    mesh: *const IsobarFeMesh,
    index: usize,
    name: *mut *const c_char,
    components: *mut usize,
    data: *mut *const f64,
) -> IsobarStatus {
    guard(|| {
        let m = non_null(mesh, "mesh")?;
        attribute_out(&m.mesh.point_data, &m.names, index, name, components, data)
    })
}

/// Number of points of a mesh (0 for NULL).
#[no_mangle]
pub extern "C" fn isobar_fe_mesh_point_count(mesh: *const IsobarFeMesh) -> usize {
    // SAFETY: null or a live handle.
    unsafe { mesh.as_ref() }.map_or(0, |m| m.mesh.given_points())
}

/// Number of volume cells of a mesh (0 for NULL): the vertex, line and surface cells given
/// beside them are left out (cell ids the core returns still count them).
#[no_mangle]
pub extern "C" fn isobar_fe_mesh_cell_count(mesh: *const IsobarFeMesh) -> usize {
    // SAFETY: null or a live handle.
    unsafe { mesh.as_ref() }.map_or(0, |m| m.mesh.cell_count())
}

/// The box that holds every cell of a mesh, curved cells' bulges included: the box whose
/// diagonal a spacing of 0 takes 1/40 of. Writes lo xyz, then hi xyz, to `bounds_out`
/// (6 f64). A data-parallel host that samples the pieces of one mesh reduces its pieces'
/// boxes and passes the whole mesh's spacing, so that every piece is sampled alike.
#[no_mangle]
pub extern "C" fn isobar_fe_mesh_bounds(
    mesh: *const IsobarFeMesh,
    bounds_out: *mut f64,
) -> IsobarStatus {
    guard(|| {
        let m = non_null(mesh, "mesh")?;
        let (lo, hi) = m.mesh.bounds();
        // Six doubles, as documented: [f64; 6] has f64's alignment.
        let out = bounds_out.cast::<[f64; 6]>();
        put(out, [lo.x, lo.y, lo.z, hi.x, hi.y, hi.z], "bounds_out")
    })
}

/// Frees a mesh (NULL is ignored).
#[no_mangle]
pub extern "C" fn isobar_fe_mesh_free(mesh: *mut IsobarFeMesh) {
    free_boxed(mesh);
}

/// Evaluates the scalar point array `field` at `n` world points (`points`: n × 3 f64,
/// xyz): finds the cell holding each point, inverts that cell's mapping T by Newton's
/// method and interpolates the field with the cell's Lagrange basis. Writes `values_out[i]`
/// (NaN where no cell holds point i) and, unless NULL, `cell_out[i]` (the cell, -1
/// outside the mesh) and `reference_out[3 i..3 i + 3]` (the reference coordinates in that
/// cell, NaN outside). A point with a NaN or infinite coordinate is refused, naming its
/// index, before anything is written. Thread-safe on a shared mesh; the first call builds
/// the mesh's cell index.
#[no_mangle]
pub extern "C" fn isobar_fe_probe(
    mesh: *const IsobarFeMesh,
    field: *const c_char,
    points: *const f64,
    n: usize,
    values_out: *mut f64,
    cell_out: *mut i64,
    reference_out: *mut f64,
) -> IsobarStatus {
    guard(|| {
        let m = non_null(mesh, "mesh")?;
        let field = opt_str(field, "field")?.ok_or_else(|| invalid("field", "must not be NULL"))?;
        let values = highorder::field_values(&m.mesh, &field)?;
        let len = n
            .checked_mul(3)
            .ok_or_else(|| invalid("n", format!("{n} points is too many")))?;
        let xyz = slice(points, len, "points")?;
        let mut world = Vec::with_capacity(n);
        for (i, c) in xyz.chunks_exact(3).enumerate() {
            let x = DVec3::new(c[0], c[1], c[2]);
            if !x.is_finite() {
                return Err(invalid(
                    "points",
                    format!(
                        "point {i} is ({}, {}, {}): every coordinate must be finite",
                        c[0], c[1], c[2]
                    ),
                ));
            }
            world.push(x);
        }
        let values_out = slice_out(values_out, n, "values_out")?
            .ok_or_else(|| invalid("values_out", "must not be NULL"))?;
        let cell_out = slice_out(cell_out, n, "cell_out")?;
        let reference_out = slice_out(reference_out, len, "reference_out")?;
        let hits = crate::field::fe::probe(&m.mesh, m.mesh.index(), &values, &world);
        for (i, hit) in hits.iter().enumerate() {
            values_out[i] = hit.map_or(f64::NAN, |h| h.value);
        }
        if let Some(out) = cell_out {
            for (o, hit) in out.iter_mut().zip(&hits) {
                *o = hit.map_or(-1, |h| m.mesh.given_cell(h.cell) as i64);
            }
        }
        if let Some(out) = reference_out {
            for (o, hit) in out.chunks_exact_mut(3).zip(&hits) {
                o.copy_from_slice(&hit.map_or([f64::NAN; 3], |h| {
                    m.mesh.given_reference(h.cell, h.reference).to_array()
                }));
            }
        }
        Ok(())
    })
}

/// A caller's output array of `len` items at `p`: None for NULL (an optional output, or
/// nothing to write when `len` is 0).
fn slice_out<'a, T>(
    p: *mut T,
    len: usize,
    name: &'static str,
) -> Result<Option<&'a mut [T]>, crate::Error> {
    if p.is_null() {
        return Ok(if len == 0 { Some(&mut []) } else { None });
    }
    if len
        .checked_mul(std::mem::size_of::<T>())
        .is_none_or(|b| b > isize::MAX as usize)
    {
        return Err(invalid(name, format!("length {len} is too large")));
    }
    // SAFETY: non-null, the caller promises `len` writable items not aliased meanwhile.
    Ok(Some(unsafe { std::slice::from_raw_parts_mut(p, len) }))
}

/// Samples the isosurface `params.iso` of the scalar point array `field` with the particle
/// system. The samples carry the arrays Element, Reference (3), Curvature and Energy.
#[no_mangle]
pub extern "C" fn isobar_fe_sample(
    mesh: *const IsobarFeMesh,
    field: *const c_char,
    params: *const IsobarFeParams,
    progress: IsobarProgressFn,
    user: *mut c_void,
    out: *mut *mut IsobarSamples,
) -> IsobarStatus {
    guard(|| {
        let mesh = non_null(mesh, "mesh")?;
        let field = opt_str(field, "field")?.ok_or_else(|| invalid("field", "must not be NULL"))?;
        if out.is_null() {
            return Err(invalid("out", "output pointer must not be NULL"));
        }
        let p: IsobarFeParams = super::read_versioned(
            params,
            "params",
            FE_PARAMS_V1_SIZE,
            "isobar_fe_params_default",
        )?;
        let (samples, stats) = with_progress(progress, user, |sink| {
            highorder::sample(&mesh.mesh, &field, &(&p).into(), sink)
        })?;
        let names = names_of(&samples.attributes);
        let warnings = super::warning_lines(&stats.warnings);
        let handle = IsobarSamples {
            samples,
            stats,
            names,
            warnings,
        };
        put(out, Box::into_raw(Box::new(handle)), "out")
    })
}

fn samples<'a>(s: *const IsobarSamples) -> Option<&'a IsobarSamples> {
    // SAFETY: null or a live handle.
    unsafe { s.as_ref() }
}

/// Number of samples (0 for NULL).
#[no_mangle]
pub extern "C" fn isobar_samples_count(s: *const IsobarSamples) -> usize {
    samples(s).map_or(0, |s| s.samples.len())
}

/// count × 3 f64 world positions, or NULL.
#[no_mangle]
pub extern "C" fn isobar_samples_positions(s: *const IsobarSamples) -> *const f64 {
    samples(s).map_or(std::ptr::null(), |s| s.samples.positions.as_ptr().cast())
}

/// count × 3 f32 unit normals (along the field's gradient), or NULL.
#[no_mangle]
pub extern "C" fn isobar_samples_normals(s: *const IsobarSamples) -> *const f32 {
    samples(s).map_or(std::ptr::null(), |s| s.samples.normals.as_ptr().cast())
}

/// count f64 splat radii (each sample's Voronoi cell reach: the disks cover the
/// surface), or NULL.
#[no_mangle]
pub extern "C" fn isobar_samples_radii(s: *const IsobarSamples) -> *const f64 {
    samples(s).map_or(std::ptr::null(), |s| s.samples.radii.as_ptr())
}

/// Number of per-sample arrays.
#[no_mangle]
pub extern "C" fn isobar_samples_attribute_count(s: *const IsobarSamples) -> usize {
    samples(s).map_or(0, |s| s.samples.attributes.len())
}

/// Name, components and data (count × components f64) of array `index`.
#[no_mangle]
pub extern "C" fn isobar_samples_attribute(
    s: *const IsobarSamples,
    index: usize,
    name: *mut *const c_char,
    components: *mut usize,
    data: *mut *const f64,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "samples")?;
        attribute_out(
            &s.samples.attributes,
            &s.names,
            index,
            name,
            components,
            data,
        )
    })
}

/// What the run warns about although it succeeded, one warning a line: an isovalue that
/// gave no sample (outside the field's range on the mesh). "" when there is nothing to
/// say, and for NULL. Valid until `isobar_samples_free`.
#[no_mangle]
pub extern "C" fn isobar_samples_warnings(s: *const IsobarSamples) -> *const c_char {
    // SAFETY: null or a live handle.
    unsafe { s.as_ref() }.map_or(c"".as_ptr(), |s| s.warnings.as_ptr())
}

/// Copies the run's statistics into `out` (whose `struct_size` the caller sets).
#[no_mangle]
pub extern "C" fn isobar_samples_stats(
    s: *const IsobarSamples,
    out: *mut IsobarFeStats,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "samples")?;
        let st = &s.stats;
        let full = IsobarFeStats {
            struct_size: 0,
            particles: st.particles as u64,
            seeds: st.seeds as u64,
            iterations: st.iterations as u64,
            evaluations: st.evaluations,
            splits: st.splits as u64,
            deletes: st.deletes as u64,
            spacing: st.spacing,
            max_residual: st.max_residual,
        };
        copy_versioned_out(full, out, "out")
    })
}

/// Writes the samples to a .vtp file (vertices with Normals, Radius and the arrays),
/// through a temporary file.
#[no_mangle]
pub extern "C" fn isobar_samples_write(
    s: *const IsobarSamples,
    path: *const c_char,
) -> IsobarStatus {
    guard(|| {
        let s = non_null(s, "samples")?;
        let path = opt_str(path, "path")?.ok_or_else(|| invalid("path", "must not be NULL"))?;
        crate::io::write_samples(std::path::Path::new(&path), &s.samples)
    })
}

/// Frees samples (NULL is ignored).
#[no_mangle]
pub extern "C" fn isobar_samples_free(s: *mut IsobarSamples) {
    free_boxed(s);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::highorder::tests::{grid_mesh, teardrop_field, teardrop_map, TEAR_R};
    use crate::progress::Progress;
    use std::ffi::CStr;

    /// The mesh's arrays as a host holds them (VTK-style, vtkIdType offsets).
    struct Arrays {
        points: Vec<f64>,
        types: Vec<u8>,
        offsets: Vec<i64>,
        connectivity: Vec<i64>,
        values: Vec<f64>,
    }

    fn arrays(mesh: &FeMesh) -> Arrays {
        let mut a = Arrays {
            points: mesh.points.iter().flat_map(|p| p.to_array()).collect(),
            types: Vec::new(),
            offsets: vec![0],
            connectivity: Vec::new(),
            values: mesh.point_data[0].data.clone(),
        };
        for c in 0..mesh.cell_count() {
            a.types.push(mesh.shape(c).kind.vtk_type());
            a.connectivity
                .extend(mesh.nodes(c).iter().map(|&n| n as i64));
            a.offsets.push(a.connectivity.len() as i64);
        }
        a
    }

    fn create(a: &Arrays, out: &mut *mut IsobarFeMesh) -> IsobarStatus {
        isobar_fe_mesh_create(
            a.points.as_ptr(),
            a.points.len() / 3,
            a.types.as_ptr(),
            a.types.len(),
            a.offsets.as_ptr(),
            a.connectivity.as_ptr(),
            a.connectivity.len(),
            std::ptr::null(),
            out,
        )
    }

    fn message() -> String {
        // SAFETY: the library's own thread-local message.
        unsafe { CStr::from_ptr(crate::capi::isobar_last_error_message()) }
            .to_string_lossy()
            .into_owned()
    }

    #[test]
    fn c_entry_points_sample_the_teardrop_as_the_rust_api_does() {
        let mesh = grid_mesh(2, 2, teardrop_map, |y| y.length_squared());
        let a = arrays(&mesh);
        let mut handle = std::ptr::null_mut();
        assert_eq!(create(&a, &mut handle), IsobarStatus::Ok, "{}", message());
        assert_eq!(isobar_fe_mesh_cell_count(handle), 8);
        let f = c"f";
        assert_eq!(
            isobar_fe_mesh_add_array(handle, f.as_ptr(), a.values.as_ptr(), a.values.len(), 1),
            IsobarStatus::Ok
        );
        assert_eq!(isobar_fe_mesh_array_count(handle), 1);
        let (mut name, mut components, mut data) = (std::ptr::null(), 0, std::ptr::null());
        assert_eq!(
            isobar_fe_mesh_array(handle, 0, &mut name, &mut components, &mut data),
            IsobarStatus::Ok
        );
        // SAFETY: the handle's own name and point_count values.
        assert_eq!(unsafe { CStr::from_ptr(name) }, f);
        assert_eq!(
            unsafe { std::slice::from_raw_parts(data, a.values.len()) },
            a.values
        );
        let mut params = IsobarFeParams {
            struct_size: 0,
            ..IsobarFeParams::default()
        };
        assert_eq!(isobar_fe_params_default(&mut params), IsobarStatus::Ok);
        params.iso = TEAR_R * TEAR_R;
        params.spacing = 0.12;
        let mut out = std::ptr::null_mut();
        let status = isobar_fe_sample(
            handle,
            f.as_ptr(),
            &params,
            None,
            std::ptr::null_mut(),
            &mut out,
        );
        assert_eq!(status, IsobarStatus::Ok, "{}", message());

        let rust = highorder::sample(&mesh, "f", &(&params).into(), &mut Progress::none())
            .unwrap()
            .0;
        let n = isobar_samples_count(out);
        assert_eq!(n, rust.len());
        assert!(n > 100);
        // SAFETY: n × 3 positions / normals and n radii, valid until isobar_samples_free.
        let (positions, normals, radii) = unsafe {
            (
                std::slice::from_raw_parts(isobar_samples_positions(out), 3 * n),
                std::slice::from_raw_parts(isobar_samples_normals(out), 3 * n),
                std::slice::from_raw_parts(isobar_samples_radii(out), n),
            )
        };
        assert_eq!(positions, rust.positions.concat());
        assert_eq!(normals, rust.normals.concat());
        assert_eq!(radii, rust.radii);
        for p in positions.chunks_exact(3) {
            let x = DVec3::new(p[0], p[1], p[2]);
            assert!(teardrop_field(x).abs() <= params.tolerance * (1.0 + 1e-9));
        }
        let mut names = Vec::new();
        for i in 0..isobar_samples_attribute_count(out) {
            let (mut name, mut components, mut data) = (std::ptr::null(), 0, std::ptr::null());
            assert_eq!(
                isobar_samples_attribute(out, i, &mut name, &mut components, &mut data),
                IsobarStatus::Ok
            );
            // SAFETY: a NUL-terminated name and n × components values owned by `out`.
            let name = unsafe { CStr::from_ptr(name) }
                .to_str()
                .unwrap()
                .to_string();
            let values = unsafe { std::slice::from_raw_parts(data, n * components) };
            assert_eq!(values, rust.attribute(&name).unwrap().data);
            names.push(name);
        }
        assert_eq!(names, ["Element", "Reference", "Curvature", "Energy"]);
        let mut stats = IsobarFeStats {
            struct_size: std::mem::size_of::<IsobarFeStats>() as u32,
            ..IsobarFeStats::default()
        };
        assert_eq!(isobar_samples_stats(out, &mut stats), IsobarStatus::Ok);
        assert_eq!(stats.particles as usize, n);
        assert!(stats.evaluations > 0 && stats.max_residual <= params.tolerance);
        isobar_samples_free(out);
        isobar_fe_mesh_free(handle);
    }

    /// A field in the order-2 space of `grid_mesh` cells (the grid coordinate y is affine
    /// in each cell's reference coordinates), not symmetric under swapping axes, so a
    /// probe that mixed up coordinates would not pass either.
    fn quadratic(y: DVec3) -> f64 {
        0.7 + y.x + 2.0 * y.y - 0.5 * y.z + y.x * y.z + 0.3 * y.y * y.y
    }

    /// The teardrop map inverted in closed form: world x back to the grid coordinate y.
    fn teardrop_inverse(x: DVec3) -> DVec3 {
        let w = crate::highorder::tests::TEAR_A + crate::highorder::tests::TEAR_B * x.z;
        DVec3::new(x.x / w, x.y / w, x.z)
    }

    /// Deterministic uniform numbers in [0, 1) (xorshift64*).
    fn uniform(state: &mut u64) -> f64 {
        *state ^= *state >> 12;
        *state ^= *state << 25;
        *state ^= *state >> 27;
        (state.wrapping_mul(0x2545_F491_4F6C_DD1D) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Probes `points` (xyz) for `field`: (status, values, cells, reference coordinates),
    /// the outputs prefilled with sentinels so an untouched entry shows.
    fn probe(
        handle: *const IsobarFeMesh,
        field: &CStr,
        points: &[f64],
    ) -> (IsobarStatus, Vec<f64>, Vec<i64>, Vec<f64>) {
        let n = points.len() / 3;
        let (mut values, mut cells, mut reference) =
            (vec![-7.0; n], vec![-7; n], vec![-7.0; 3 * n]);
        let status = isobar_fe_probe(
            handle,
            field.as_ptr(),
            points.as_ptr(),
            n,
            values.as_mut_ptr(),
            cells.as_mut_ptr(),
            reference.as_mut_ptr(),
        );
        (status, values, cells, reference)
    }

    #[test]
    fn probe_inverts_curved_cells_and_reproduces_a_quadratic_field() {
        // 2³ order-2 hexahedra through the teardrop map: curved faces, non-affine cells
        // whose Jacobian varies by a factor of 7 between the narrow and wide ends.
        let (n, p) = (2, 2);
        let mesh = grid_mesh(n, p, teardrop_map, quadratic);
        let a = arrays(&mesh);
        let mut handle = std::ptr::null_mut();
        assert_eq!(create(&a, &mut handle), IsobarStatus::Ok, "{}", message());
        assert_eq!(
            isobar_fe_mesh_add_array(handle, c"q".as_ptr(), a.values.as_ptr(), a.values.len(), 1),
            IsobarStatus::Ok
        );

        // Random interior points, away from the faces between cells so the holding cell
        // is unique: y in the open grid cube, x = T(y).
        let mut state = 0x9E37_79B9_7F4A_7C15u64;
        let mut ys = Vec::new();
        while ys.len() < 500 {
            let y = DVec3::new(
                uniform(&mut state),
                uniform(&mut state),
                uniform(&mut state),
            ) * 1.998
                - 0.999;
            if y.abs().min_element() > 1e-3 {
                ys.push(y);
            }
        }
        let points: Vec<f64> = ys
            .iter()
            .flat_map(|&y| teardrop_map(y).to_array())
            .collect();
        let (status, values, cells, reference) = probe(handle, c"q", &points);
        assert_eq!(status, IsobarStatus::Ok, "{}", message());
        for (i, &y) in ys.iter().enumerate() {
            let x = DVec3::from_slice(&points[3 * i..]);
            // The analytic field at the world point, through the closed-form inverse.
            let want = quadratic(teardrop_inverse(x));
            assert!(
                (values[i] - want).abs() <= 1e-10,
                "point {i} {x:?}: probe {} vs analytic {want}",
                values[i]
            );
            // The grid cell holding y and y's reference coordinates in it ([0, 1]³).
            let g = (y + 1.0) * 0.5 * n as f64;
            let ijk = g.floor();
            let cell = ijk.x + n as f64 * (ijk.y + n as f64 * ijk.z);
            assert_eq!(cells[i], cell as i64, "point {i} {x:?}");
            let u = DVec3::from_slice(&reference[3 * i..]);
            assert!(
                u.distance(g - ijk) <= 1e-10,
                "point {i}: reference {u:?} vs {:?}",
                g - ijk
            );
        }

        // Outside: past a side, below the narrow end, far away; and one inside point
        // among them keeps its value.
        let outside = [
            teardrop_map(DVec3::new(1.2, 0.1, 0.0)),
            teardrop_map(DVec3::new(0.0, -1.1, 0.5)),
            teardrop_map(DVec3::new(0.2, 0.3, -1.05)),
            DVec3::new(10.0, -3.0, 4.0),
            teardrop_map(DVec3::new(0.25, -0.5, 0.75)),
        ];
        let points: Vec<f64> = outside.iter().flat_map(|x| x.to_array()).collect();
        let (status, values, cells, reference) = probe(handle, c"q", &points);
        assert_eq!(status, IsobarStatus::Ok, "{}", message());
        for i in 0..4 {
            assert_eq!(cells[i], -1, "point {i} {:?}", outside[i]);
            assert!(values[i].is_nan() && reference[3 * i..3 * i + 3].iter().all(|r| r.is_nan()));
        }
        assert_eq!(cells[4], 5);
        assert!((values[4] - quadratic(DVec3::new(0.25, -0.5, 0.75))).abs() <= 1e-10);

        // On the mesh boundary a rounding error outside (5e-9 reference units past cell 0's
        // face x = -1) still counts, extrapolated by the cell's polynomial; 1e-6 out does not.
        let edge = [
            DVec3::new(-1.0 - 5e-9, -0.4, -0.3),
            DVec3::new(-1.0 - 1e-6, -0.4, -0.3),
        ];
        let points: Vec<f64> = edge
            .iter()
            .flat_map(|&y| teardrop_map(y).to_array())
            .collect();
        let (status, values, cells, _) = probe(handle, c"q", &points);
        assert_eq!(status, IsobarStatus::Ok, "{}", message());
        assert_eq!(cells, [0, -1]);
        assert!((values[0] - quadratic(edge[0])).abs() <= 1e-10 && values[1].is_nan());

        // Optional outputs may be NULL; no points is no work.
        let mut value = 0.0;
        let inside = teardrop_map(DVec3::new(0.5, 0.5, 0.5)).to_array();
        let status = isobar_fe_probe(
            handle,
            c"q".as_ptr(),
            inside.as_ptr(),
            1,
            &mut value,
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        );
        assert_eq!(status, IsobarStatus::Ok, "{}", message());
        assert!((value - quadratic(DVec3::splat(0.5))).abs() <= 1e-10);
        let status = isobar_fe_probe(
            handle,
            c"q".as_ptr(),
            std::ptr::null(),
            0,
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        );
        assert_eq!(status, IsobarStatus::Ok, "{}", message());
        isobar_fe_mesh_free(handle);
    }

    #[test]
    fn probe_refuses_nan_points_and_unknown_fields_naming_them() {
        let mesh = grid_mesh(1, 2, teardrop_map, quadratic);
        let a = arrays(&mesh);
        let mut handle = std::ptr::null_mut();
        assert_eq!(create(&a, &mut handle), IsobarStatus::Ok, "{}", message());
        assert_eq!(
            isobar_fe_mesh_add_array(handle, c"q".as_ptr(), a.values.as_ptr(), a.values.len(), 1),
            IsobarStatus::Ok
        );
        let mut points = [
            0.1,
            0.2,
            0.3,
            0.0,
            0.0,
            0.0,
            0.4,
            f64::NAN,
            0.0,
            0.0,
            0.1,
            0.0,
        ];
        let (status, values, cells, _) = probe(handle, c"q", &points);
        assert_eq!(status, IsobarStatus::ErrInvalidArgument);
        let m = message();
        assert!(m.contains("point 2 ") && m.contains("NaN"), "{m}");
        // Refused before anything was written.
        assert!(values.iter().all(|&v| v == -7.0) && cells.iter().all(|&c| c == -7));
        points[7] = f64::INFINITY;
        assert_eq!(
            probe(handle, c"q", &points).0,
            IsobarStatus::ErrInvalidArgument
        );
        assert!(message().contains("point 2 "), "{}", message());
        points[7] = 0.0;

        let (status, values, ..) = probe(handle, c"nope", &points);
        assert_eq!(status, IsobarStatus::ErrInvalidInput);
        assert!(
            message().contains("'nope'") && message().contains("q"),
            "{}",
            message()
        );
        assert!(values.iter().all(|&v| v == -7.0));
        let status = isobar_fe_probe(
            handle,
            c"q".as_ptr(),
            points.as_ptr(),
            4,
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        );
        assert_eq!(status, IsobarStatus::ErrInvalidArgument);
        assert!(message().contains("values_out"), "{}", message());
        let status = isobar_fe_probe(
            std::ptr::null(),
            c"q".as_ptr(),
            points.as_ptr(),
            4,
            std::ptr::null_mut(),
            std::ptr::null_mut(),
            std::ptr::null_mut(),
        );
        assert_eq!(status, IsobarStatus::ErrInvalidArgument);
        assert!(message().contains("mesh"), "{}", message());
        isobar_fe_mesh_free(handle);
    }

    #[test]
    fn bad_meshes_and_calls_are_refused_with_a_message() {
        let mesh = grid_mesh(1, 2, |y| y, |y| y.x);
        let good = arrays(&mesh);
        let mut handle = std::ptr::null_mut();

        // Pull the body node through the top face: along z the mapping runs back near it,
        // so det J is negative there and positive below (a mesh mirrored as a whole, with
        // det J negative throughout, is read).
        let mut inverted = arrays(&mesh);
        let body = inverted
            .points
            .chunks_exact_mut(3)
            .find(|p| p.iter().all(|c| c.abs() < 1e-12))
            .unwrap();
        body[2] = 5.0;
        assert_eq!(
            create(&inverted, &mut handle),
            IsobarStatus::ErrInvalidInput
        );
        assert!(
            message().contains("cell 0") && message().contains("inverted"),
            "{}",
            message()
        );
        let mut mirrored = arrays(&mesh);
        for p in mirrored.points.chunks_exact_mut(3) {
            p[0] = -p[0];
        }
        assert_eq!(create(&mirrored, &mut handle), IsobarStatus::Ok);
        isobar_fe_mesh_free(handle);
        handle = std::ptr::null_mut();

        let mut out_of_range = arrays(&mesh);
        out_of_range.connectivity[3] = 1_000;
        assert_eq!(
            create(&out_of_range, &mut handle),
            IsobarStatus::ErrInvalidInput
        );
        assert!(message().contains("point 1000"), "{}", message());

        let mut negative = arrays(&mesh);
        negative.connectivity[0] = -1;
        assert_eq!(
            create(&negative, &mut handle),
            IsobarStatus::ErrInvalidArgument
        );
        assert!(message().contains("connectivity"), "{}", message());

        assert_eq!(create(&good, &mut handle), IsobarStatus::Ok);
        let short = [0.0f64; 3];
        assert_eq!(
            isobar_fe_mesh_add_array(handle, c"f".as_ptr(), short.as_ptr(), 1, 3),
            IsobarStatus::ErrInvalidArgument
        );
        assert!(message().contains("points"), "{}", message());
        let mut out = std::ptr::null_mut();
        let params = IsobarFeParams::default();
        assert_eq!(
            isobar_fe_sample(
                handle,
                c"nope".as_ptr(),
                &params,
                None,
                std::ptr::null_mut(),
                &mut out
            ),
            IsobarStatus::ErrInvalidInput
        );
        assert!(message().contains("nope"), "{}", message());
        assert!(out.is_null());
        let stale = IsobarFeParams {
            struct_size: 8,
            ..IsobarFeParams::default()
        };
        assert_eq!(
            isobar_fe_sample(
                handle,
                c"f".as_ptr(),
                &stale,
                None,
                std::ptr::null_mut(),
                &mut out
            ),
            IsobarStatus::ErrInvalidArgument
        );
        isobar_fe_mesh_free(handle);
        assert_eq!(
            isobar_fe_mesh_read(c"/nonexistent/mesh.vtu".as_ptr(), &mut handle),
            IsobarStatus::ErrIo
        );
    }
}
