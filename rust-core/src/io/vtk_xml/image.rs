//! VTK XML ImageData (`.vti`): a regular volume. Pieces are placed into the whole extent by
//! their own extents; the scalar array is the one named, else the point data's active
//! `Scalars`, else its first one-component numeric array.

use super::document::Document;
use crate::error::{Error, Result};
use crate::io::numeric::Scalar;

/// The volume of an ImageData file: whole-extent node counts, origin (of the whole
/// extent's first node), spacing, the array's element type and its values, x fastest.
pub(crate) struct ImageVolume {
    pub(crate) dims: [usize; 3],
    pub(crate) origin: [f64; 3],
    pub(crate) spacing: [f64; 3],
    pub(crate) ty: Scalar,
    pub(crate) values: Vec<f64>,
    pub(crate) array: String,
}

/// Reads the scalar array `array` (or the default choice, see the module docs).
pub(crate) fn read_image(bytes: &[u8], name: &str, array: Option<&str>) -> Result<ImageVolume> {
    let doc = Document::parse(bytes, name)?;
    let err = |m: String| Error::format(name, m);
    if doc.kind != "ImageData" {
        return Err(err(format!(
            "a volume must be VTK ImageData, this file holds {}",
            doc.kind
        )));
    }
    let geometry = doc
        .image
        .ok_or_else(|| err("no <ImageData> element".into()))?;
    let we = geometry.whole_extent;
    let mut dims = [0usize; 3];
    for a in 0..3 {
        let n = we[2 * a + 1] - we[2 * a] + 1;
        if !(1..=1 << 20).contains(&n) {
            return Err(err(format!(
                "WholeExtent {:?} gives {n} nodes along axis {a}",
                we
            )));
        }
        dims[a] = n as usize;
    }
    let total = dims[0]
        .checked_mul(dims[1])
        .and_then(|n| n.checked_mul(dims[2]))
        .ok_or_else(|| err("WholeExtent is impossibly large".into()))?;
    // The pieces are decoded before the volume is allocated: a header can claim any
    // extent, and only data actually in the file may size an allocation. A file of
    // several pieces then holds them and the volume at once (twice the volume at the
    // peak); the usual single piece becomes the volume without a copy.
    let mut decoded: Vec<([i64; 6], [usize; 3], Vec<f64>)> = Vec::new();
    let mut covered = 0usize;
    let mut chosen: Option<(String, Scalar)> = None;
    for (k, piece) in doc.pieces.iter().enumerate() {
        let e = piece.extent.unwrap_or(we);
        let mut pd = [0usize; 3];
        for a in 0..3 {
            if e[2 * a] < we[2 * a] || e[2 * a + 1] > we[2 * a + 1] || e[2 * a + 1] < e[2 * a] {
                return Err(err(format!(
                    "piece {k} extent {e:?} lies outside the WholeExtent {we:?}"
                )));
            }
            pd[a] = (e[2 * a + 1] - e[2 * a] + 1) as usize;
        }
        let points = pd[0] * pd[1] * pd[2];
        let candidates: Vec<_> = piece
            .arrays
            .iter()
            .filter(|a| a.section == "PointData" && a.ty.is_some())
            .collect();
        let wanted: Option<&str> = chosen.as_ref().map(|(n, _)| n.as_str()).or(array);
        let found = match wanted {
            Some(n) => candidates.iter().find(|a| a.name == n).copied(),
            None => candidates
                .iter()
                .find(|a| Some(&a.name) == piece.scalars_name.as_ref())
                .or_else(|| candidates.iter().find(|a| a.components == 1))
                .copied(),
        };
        let Some(a) = found else {
            let names: Vec<String> = candidates
                .iter()
                .map(|a| format!("{} ({} components)", a.name, a.components))
                .collect();
            return Err(err(format!(
                "piece {k}: no point array {} (point arrays: {})",
                array.map_or("with one component".to_string(), |n| format!("'{n}'")),
                if names.is_empty() {
                    "none".into()
                } else {
                    names.join(", ")
                }
            )));
        };
        if a.components != 1 {
            return Err(err(format!(
                "point array '{}' has {} components; a volume needs a scalar (1 component) array",
                a.name, a.components
            )));
        }
        let ty = a.ty.unwrap_or(Scalar::F64);
        chosen.get_or_insert((a.name.clone(), ty));
        decoded.push((e, pd, doc.values(a, points)?));
        covered += points;
    }
    if covered < total {
        return Err(err(format!(
            "the pieces cover {covered} of the {total} nodes of the WholeExtent"
        )));
    }
    let values = match decoded.pop() {
        // One piece over the whole extent (the usual file) is the volume as it is.
        Some((_, pd, data)) if decoded.is_empty() && pd == dims => data,
        last => {
            let mut values = vec![0.0; total];
            for (e, pd, data) in decoded.into_iter().chain(last) {
                for z in 0..pd[2] {
                    for y in 0..pd[1] {
                        let gy = (e[2] - we[2]) as usize + y;
                        let gz = (e[4] - we[4]) as usize + z;
                        let gx = (e[0] - we[0]) as usize;
                        let dst = gx + dims[0] * (gy + dims[1] * gz);
                        let src = pd[0] * (y + pd[1] * z);
                        values[dst..dst + pd[0]].copy_from_slice(&data[src..src + pd[0]]);
                    }
                }
            }
            values
        }
    };
    let (array, ty) = chosen.ok_or_else(|| err("no pieces".into()))?;
    let origin =
        std::array::from_fn(|a| geometry.origin[a] + we[2 * a] as f64 * geometry.spacing[a]);
    Ok(ImageVolume {
        dims,
        origin,
        spacing: geometry.spacing,
        ty,
        values,
        array,
    })
}
