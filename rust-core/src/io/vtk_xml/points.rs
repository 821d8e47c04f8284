//! The `.vtp` writer for oriented point samples: Verts, Normals, Radius and every array.

use super::write::{write_polydata, Array, Cells, PolyData, Values};
use crate::samples::PointSamples;
use std::io::Write;

/// Writes `samples` as VTK XML PolyData with one vertex cell per point (raw appended):
/// Points Float64, PointData Normals (Float32, marked as the normals), Radius (Float64)
/// and every attribute (Float64). ParaView shows it as point gaussians scaled by Radius.
pub(crate) fn write_points(w: &mut dyn Write, samples: &PointSamples) -> std::io::Result<()> {
    let n = samples.len();
    let mut point_data = vec![
        Array::new("Normals", 3, Values::F32(samples.normals.as_flattened())),
        Array::new("Radius", 1, Values::F64(&samples.radii)),
    ];
    for a in &samples.attributes {
        point_data.push(Array::new(&a.name, a.components, Values::F64(&a.data)));
    }
    write_polydata(
        w,
        &PolyData {
            points: samples.positions.as_flattened(),
            point_data,
            active: " Normals=\"Normals\" Scalars=\"Radius\"",
            cells: Cells {
                kind: "Verts",
                count: n,
                connectivity: Values::I64(&|k| k as i64, n),
                offsets: Values::I64(&|k| k as i64 + 1, n),
            },
        },
    )
}
