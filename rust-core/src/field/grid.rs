//! Regular volumes: node values on a uniform (possibly anisotropic) lattice, x fastest, as
//! scanners and simulation codes write them. A [`Volume`] is a [`ScalarField`] through
//! trilinear interpolation, and gives the node gradients (central differences) that
//! vertex normals of grid isosurfaces are interpolated from.

use super::ScalarField;
use crate::divisor::Divisor;
use crate::error::{Error, Result};
use glam::DVec3;

/// Element type of a volume's values. Files of other numeric types are converted to f32.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ValueType {
    F32,
    U16,
    U8,
}

impl ValueType {
    /// Bytes per value.
    pub fn size(self) -> usize {
        match self {
            ValueType::F32 => 4,
            ValueType::U16 => 2,
            ValueType::U8 => 1,
        }
    }

    /// Stable code used in files.
    pub fn code(self) -> u8 {
        match self {
            ValueType::F32 => 1,
            ValueType::U16 => 2,
            ValueType::U8 => 3,
        }
    }

    /// Inverse of [`ValueType::code`].
    pub fn from_code(code: u8) -> Option<Self> {
        match code {
            1 => Some(ValueType::F32),
            2 => Some(ValueType::U16),
            3 => Some(ValueType::U8),
            _ => None,
        }
    }

    /// Lower-case name ("f32", "u16", "u8").
    pub fn name(self) -> &'static str {
        match self {
            ValueType::F32 => "f32",
            ValueType::U16 => "u16",
            ValueType::U8 => "u8",
        }
    }
}

/// Node values in their native type (u16 and u8 convert to f32 exactly).
#[derive(Clone, Debug, PartialEq)]
pub enum Values {
    F32(Vec<f32>),
    U16(Vec<u16>),
    U8(Vec<u8>),
}

impl Values {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            Values::F32(v) => v.len(),
            Values::U16(v) => v.len(),
            Values::U8(v) => v.len(),
        }
    }

    /// True when there are no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Value `i` as f32.
    #[inline]
    pub fn get(&self, i: usize) -> f32 {
        match self {
            Values::F32(v) => v[i],
            Values::U16(v) => v[i] as f32,
            Values::U8(v) => v[i] as f32,
        }
    }

    /// The element type.
    pub fn value_type(&self) -> ValueType {
        match self {
            Values::F32(_) => ValueType::F32,
            Values::U16(_) => ValueType::U16,
            Values::U8(_) => ValueType::U8,
        }
    }
}

/// Coordinates of a lattice's node indices by multiplication ([`Divisor`]) instead of
/// [`Lattice::coords`]' two `div`s: for loops that turn many indices into coordinates
/// (the slider's map keys). Indices must be below 2³².
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct NodeCoords {
    x: Divisor,
    y: Divisor,
}

impl NodeCoords {
    pub(crate) fn new(lattice: &Lattice) -> NodeCoords {
        let axis = |a: usize| Divisor::new(u32::try_from(lattice.dims[a]).expect("dims below 2³²"));
        NodeCoords {
            x: axis(0),
            y: axis(1),
        }
    }

    /// (x, y, z) of node `i` (< 2³²), as [`Lattice::coords`] gives them.
    #[inline(always)]
    pub(crate) fn coords(self, i: usize) -> [usize; 3] {
        debug_assert!(i <= u32::MAX as usize);
        let (r, x) = self.x.div_rem(i as u32);
        let (z, y) = self.y.div_rem(r);
        [x as usize, y as usize, z as usize]
    }
}

/// Node positions of a regular lattice: node (x, y, z) sits at `origin + (x, y, z) * spacing`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lattice {
    /// Nodes per axis, each at least 2.
    pub dims: [usize; 3],
    pub origin: DVec3,
    /// Node spacing per axis, positive.
    pub spacing: DVec3,
}

impl Lattice {
    /// Checks dimensions (≥ 2 nodes per axis) and geometry (finite, positive spacing).
    pub fn new(dims: [usize; 3], origin: DVec3, spacing: DVec3) -> Result<Self> {
        if dims.iter().any(|&d| d < 2) {
            return Err(Error::InvalidInput(format!(
                "a volume needs at least 2 nodes along every axis, got {}×{}×{}",
                dims[0], dims[1], dims[2]
            )));
        }
        if !origin.is_finite() {
            return Err(Error::InvalidInput(format!(
                "volume origin {:?} is not finite",
                origin.to_array()
            )));
        }
        if !(spacing.is_finite() && spacing.min_element() > 0.0) {
            return Err(Error::InvalidInput(format!(
                "volume spacing {:?} must be positive and finite",
                spacing.to_array()
            )));
        }
        Ok(Lattice {
            dims,
            origin,
            spacing,
        })
    }

    /// Number of nodes.
    pub fn node_count(&self) -> usize {
        self.dims.iter().product()
    }

    /// Linear index of node (x, y, z), x fastest.
    #[inline]
    pub fn index(&self, x: usize, y: usize, z: usize) -> usize {
        x + self.dims[0] * (y + self.dims[1] * z)
    }

    /// (x, y, z) of a linear node index.
    #[inline]
    pub fn coords(&self, i: usize) -> [usize; 3] {
        let x = i % self.dims[0];
        let r = i / self.dims[0];
        [x, r % self.dims[1], r / self.dims[1]]
    }

    /// Linear index step of one node along `axis`.
    #[inline]
    pub fn stride(&self, axis: usize) -> usize {
        match axis {
            0 => 1,
            1 => self.dims[0],
            _ => self.dims[0] * self.dims[1],
        }
    }

    /// Position of node (x, y, z).
    #[inline]
    pub fn position(&self, c: [usize; 3]) -> DVec3 {
        self.origin + DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64) * self.spacing
    }

    /// Position at parameter `t` along the lattice edge from node `c` in direction `axis`.
    /// Every grid extractor places vertices with this, so their meshes agree bit for bit.
    #[inline]
    pub fn edge_point(&self, c: [usize; 3], axis: usize, t: f64) -> DVec3 {
        let mut g = DVec3::new(c[0] as f64, c[1] as f64, c[2] as f64);
        g[axis] += t;
        self.origin + g * self.spacing
    }
}

/// A regular volume: a lattice and one value per node.
#[derive(Clone, Debug, PartialEq)]
pub struct Volume {
    pub lattice: Lattice,
    pub values: Values,
    /// What reading the values lost although they were accepted (see [`Narrowing`]).
    pub warnings: Vec<String>,
}

/// Values wider than f32 (f64, 32- and 64-bit integers) narrowed to the f32 a volume
/// holds, and what the narrowing loses. A finite value beyond f32's range would turn
/// infinite and be blamed on the data: refused, naming it. A value range that f32
/// resolves in fewer than 10,000 steps (a field offset far from zero, as a pressure of
/// 101325 ± 0.02 Pa, becomes a few hundred steps) gives the surfaces of the rounded
/// values: warned about, with the remedy.
#[derive(Clone, Copy, Debug)]
pub struct Narrowing {
    lo: f64,
    hi: f64,
    seen: usize,
    beyond: Option<(usize, f64)>,
}

impl Default for Narrowing {
    fn default() -> Self {
        Narrowing {
            lo: f64::INFINITY,
            hi: f64::NEG_INFINITY,
            seen: 0,
            beyond: None,
        }
    }
}

impl Narrowing {
    /// The next value (in node order) as f32.
    #[inline]
    pub fn narrow(&mut self, v: f64) -> f32 {
        let f = v as f32;
        if v.is_finite() {
            self.lo = self.lo.min(v);
            self.hi = self.hi.max(v);
            if f.is_infinite() && self.beyond.is_none() {
                self.beyond = Some((self.seen, v));
            }
        }
        self.seen += 1;
        f
    }

    /// The volume of the narrowed `values` on `lattice`, carrying the precision warning.
    pub fn finish(self, lattice: Lattice, values: Vec<f32>) -> Result<Volume> {
        if let Some((i, v)) = self.beyond {
            let [x, y, z] = lattice.coords(i);
            return Err(Error::InvalidInput(format!(
                "volume value at node {i} (x={x}, y={y}, z={z}) is {v:e}, beyond the range of \
                 float32, which volumes are held in; scale the values first"
            )));
        }
        let mut volume = Volume::new(lattice, Values::F32(values))?;
        volume.warnings.extend(self.warning());
        Ok(volume)
    }

    fn warning(&self) -> Option<String> {
        let (lo, hi) = (self.lo, self.hi);
        if hi <= lo {
            return None;
        }
        let largest = lo.abs().max(hi.abs()) as f32;
        // The gap from `largest` to the next f32: the step of the rounded values there
        // (below it at f32::MAX, where there is no next one).
        let above = f32::from_bits(largest.to_bits() + 1);
        let step = match above.is_finite() {
            true => (above - largest) as f64,
            false => (largest - f32::from_bits(largest.to_bits() - 1)) as f64,
        };
        // Fixed decimals that tell the range's ends apart (three digits of its width).
        let decimals = (2.0 - (hi - lo).log10().floor()).clamp(0.0, 12.0) as usize;
        let show = |v: f64| match v.abs() < 1e9 {
            true => format!("{v:.decimals$}"),
            false => format!("{v:e}"),
        };
        let step_text = match (1e-4..1e9).contains(&step) {
            true => format!("{step}"),
            false => format!("{step:e}"),
        };
        (step > 1e-4 * (hi - lo)).then(|| {
            format!(
                "the values are held as float32, in steps of {step_text} near {}: {:.2} % of the \
                 value range {}..{}; subtract an offset (e.g. the mean) first to keep the \
                 surfaces of the exact values",
                show(largest as f64),
                100.0 * step / (hi - lo),
                show(lo),
                show(hi)
            )
        })
    }
}

impl Volume {
    /// Checks that there is one value per node and that no value is NaN or infinite
    /// (the error names the first bad node).
    pub fn new(lattice: Lattice, values: Values) -> Result<Self> {
        let n = lattice.node_count();
        if values.len() != n {
            return Err(Error::InvalidInput(format!(
                "a {}×{}×{} volume needs {n} values, got {}",
                lattice.dims[0],
                lattice.dims[1],
                lattice.dims[2],
                values.len()
            )));
        }
        if let Values::F32(v) = &values {
            if let Some(i) = v.iter().position(|x| !x.is_finite()) {
                let [x, y, z] = lattice.coords(i);
                return Err(Error::InvalidInput(format!(
                    "volume value at node {i} (x={x}, y={y}, z={z}) is {}",
                    v[i]
                )));
            }
        }
        Ok(Volume {
            lattice,
            values,
            warnings: Vec::new(),
        })
    }

    /// Reverses the node order along `axis`, with the origin moved to the last node, so
    /// that each value keeps its position: the volume of a file whose index runs against
    /// the axis (spacing `-self.lattice.spacing[axis]` from the origin as read).
    pub fn reverse_axis(&mut self, axis: usize) {
        fn reverse<T>(v: &mut [T], dims: [usize; 3], axis: usize) {
            let stride = [1, dims[0], dims[0] * dims[1]][axis];
            let n = dims[axis];
            for start in 0..v.len() {
                // Each line along `axis` once, from its node at index 0.
                if (start / stride).is_multiple_of(n) {
                    for i in 0..n / 2 {
                        v.swap(start + i * stride, start + (n - 1 - i) * stride);
                    }
                }
            }
        }
        let dims = self.lattice.dims;
        match &mut self.values {
            Values::F32(v) => reverse(v, dims, axis),
            Values::U16(v) => reverse(v, dims, axis),
            Values::U8(v) => reverse(v, dims, axis),
        }
        self.lattice.origin[axis] -= (dims[axis] - 1) as f64 * self.lattice.spacing[axis];
    }

    /// Value at node (x, y, z).
    #[inline]
    pub fn at(&self, x: usize, y: usize, z: usize) -> f32 {
        self.values.get(self.lattice.index(x, y, z))
    }

    /// Smallest and largest value.
    pub fn range(&self) -> (f32, f32) {
        (0..self.values.len()).fold((f32::INFINITY, f32::NEG_INFINITY), |(lo, hi), i| {
            let v = self.values.get(i);
            (lo.min(v), hi.max(v))
        })
    }

    /// Gradient at a node by central differences (one-sided on the boundary).
    pub fn node_gradient(&self, c: [usize; 3]) -> DVec3 {
        node_gradient(&self.lattice, |n| self.at(n[0], n[1], n[2]), c)
    }
}

/// Gradient at node `c` of values given by `value(node)`, by central differences inside
/// and one-sided differences on the boundary. Shared by the volume and the slider's
/// store (which finds values by coordinates: its layout is bricked) so both give the
/// same normals.
#[inline]
pub fn node_gradient(lattice: &Lattice, value: impl Fn([usize; 3]) -> f32, c: [usize; 3]) -> DVec3 {
    let mut g = DVec3::ZERO;
    for a in 0..3 {
        let (mut lo, mut hi) = (c, c);
        let span = if c[a] == 0 {
            hi[a] += 1;
            1.0
        } else if c[a] + 1 == lattice.dims[a] {
            lo[a] -= 1;
            1.0
        } else {
            lo[a] -= 1;
            hi[a] += 1;
            2.0
        };
        g[a] = (value(hi) as f64 - value(lo) as f64) / (span * lattice.spacing[a]);
    }
    g
}

impl Lattice {
    /// Cell (lower corner) holding the point at lattice index coordinates `g`, and the
    /// local coordinates in [0, 1]³; points outside are clamped to the nearest cell.
    pub fn cell_at(&self, g: DVec3) -> ([usize; 3], DVec3) {
        let mut c = [0usize; 3];
        let mut f = DVec3::ZERO;
        for a in 0..3 {
            let max_cell = (self.dims[a] - 2) as f64;
            let cell = g[a].floor().clamp(0.0, max_cell);
            c[a] = cell as usize;
            f[a] = (g[a] - cell).clamp(0.0, 1.0);
        }
        (c, f)
    }
}

/// Trilinear value and exact gradient (per unit of local coordinate) at local coordinates
/// `f` of a cell whose corner k (at `mc::corner_offset(k)`) has value `v[k]`.
pub fn trilinear(v: &[f64; 8], f: DVec3) -> (f64, DVec3) {
    let (fx, fy, fz) = (f.x, f.y, f.z);
    let c00 = v[0] * (1.0 - fx) + v[1] * fx;
    let c10 = v[2] * (1.0 - fx) + v[3] * fx;
    let c01 = v[4] * (1.0 - fx) + v[5] * fx;
    let c11 = v[6] * (1.0 - fx) + v[7] * fx;
    let c0 = c00 * (1.0 - fy) + c10 * fy;
    let c1 = c01 * (1.0 - fy) + c11 * fy;
    let value = c0 * (1.0 - fz) + c1 * fz;
    let dx = |k: usize| v[k + 1] - v[k];
    let gx =
        (dx(0) * (1.0 - fy) + dx(2) * fy) * (1.0 - fz) + (dx(4) * (1.0 - fy) + dx(6) * fy) * fz;
    let gy = (c10 - c00) * (1.0 - fz) + (c11 - c01) * fz;
    let gz = c1 - c0;
    (value, DVec3::new(gx, gy, gz))
}

impl ScalarField for Volume {
    fn value(&self, x: DVec3) -> f64 {
        self.value_and_gradient(x).0
    }

    /// Trilinear value and its exact gradient (outside the lattice: the nearest boundary
    /// cell's value at the clamped point).
    fn value_and_gradient(&self, p: DVec3) -> (f64, DVec3) {
        let l = &self.lattice;
        let (c, f) = l.cell_at((p - l.origin) / l.spacing);
        let v: [f64; 8] = std::array::from_fn(|k| {
            let [x, y, z] = crate::mc::corner_offset(k).map(|d| d as usize);
            self.at(c[0] + x, c[1] + y, c[2] + z) as f64
        });
        let (value, g) = trilinear(&v, f);
        (value, g / l.spacing)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// `values` along x of an nx×2×2 volume (nx at least 2), the rest repeating the last.
    fn narrowed(values: &[f64]) -> Result<Volume> {
        let nx = values.len().max(2);
        let lattice = Lattice::new([nx, 2, 2], DVec3::ZERO, DVec3::ONE).unwrap();
        let last = values[values.len() - 1];
        let all = (0..4 * nx).map(|i| values.get(i).copied().unwrap_or(last));
        let mut narrowing = Narrowing::default();
        let v = all.map(|x| narrowing.narrow(x)).collect();
        narrowing.finish(lattice, v)
    }

    #[test]
    fn narrowing_refuses_values_beyond_f32_and_warns_of_coarse_steps() {
        // A range f32 resolves finely: the values as f32, no warning.
        let fine = narrowed(&[0.25, -1.5, 3.0e3]).unwrap();
        assert_eq!(fine.values.get(1), -1.5);
        assert!(fine.warnings.is_empty(), "{:?}", fine.warnings);
        // 101325 ± 0.02: f32 steps of 1/128 near 101325 are 19.5 % of the range.
        let coarse = narrowed(&[101324.98, 101325.0, 101325.02]).unwrap();
        assert_eq!(coarse.warnings.len(), 1);
        let w = &coarse.warnings[0];
        assert!(
            w.contains("steps of 0.0078125 near 101325.0234: 19.53 %"),
            "{w}"
        );
        assert!(w.contains("range 101324.9800..101325.0200"), "{w}");
        // The largest finite f32 still narrows (a no-data marker: the range is huge, its
        // steps fine); past it, refused, naming node and value.
        let marked = narrowed(&[0.0, f32::MAX as f64]).unwrap();
        assert!(marked.warnings.is_empty(), "{:?}", marked.warnings);
        let near = narrowed(&[f32::MAX as f64 * 0.999999, f32::MAX as f64]).unwrap();
        assert!(
            near.warnings[0].contains("steps of 2.028240960365167e31 near 3.4028234663852886e38"),
            "{:?}",
            near.warnings
        );
        let e = narrowed(&[0.0, 1.0, -1e300, 2e300])
            .unwrap_err()
            .to_string();
        assert!(
            e.contains("node 2 (x=2, y=0, z=0) is -1e300, beyond the range of float32"),
            "{e}"
        );
        // NaN and infinities keep the message they always had (the value is as read).
        let e = narrowed(&[0.0, f64::NAN]).unwrap_err().to_string();
        assert!(e.contains("node 1 (x=1, y=0, z=0) is NaN"), "{e}");
        // One value (no range): nothing to warn about.
        assert!(narrowed(&[101325.0]).unwrap().warnings.is_empty());
    }

    #[test]
    fn trilinear_reproduces_corners_and_a_linear_field() {
        // v = x + 2y + 4z at corner k = (x, y, z): corner values exact, and the
        // interpolant of a linear field is that field, gradient (1, 2, 4) everywhere.
        let v: [f64; 8] = std::array::from_fn(|k| k as f64);
        for k in 0..8 {
            let t = DVec3::from(crate::mc::corner_offset(k).map(f64::from));
            assert_eq!(trilinear(&v, t), (v[k], DVec3::new(1.0, 2.0, 4.0)));
        }
        let t = DVec3::new(0.25, 0.5, 0.75);
        let (value, grad) = trilinear(&v, t);
        assert!((value - (0.25 + 1.0 + 3.0)).abs() < 1e-15);
        assert_eq!(grad, DVec3::new(1.0, 2.0, 4.0));
    }

    fn linear_volume() -> Volume {
        let lattice = Lattice::new(
            [4, 3, 5],
            DVec3::new(1.0, -2.0, 0.5),
            DVec3::new(0.5, 1.0, 2.0),
        )
        .unwrap();
        let mut v = Vec::new();
        for z in 0..5 {
            for y in 0..3 {
                for x in 0..4 {
                    let p = lattice.position([x, y, z]);
                    v.push((2.0 * p.x - 3.0 * p.y + 0.5 * p.z) as f32);
                }
            }
        }
        Volume::new(lattice, Values::F32(v)).unwrap()
    }

    #[test]
    fn trilinear_reproduces_a_linear_field_and_its_gradient() {
        let vol = linear_volume();
        for p in [
            DVec3::new(1.2, -1.3, 3.1),
            DVec3::new(2.4, -0.1, 8.4),
            DVec3::new(1.0, -2.0, 0.5),
        ] {
            let (v, g) = vol.value_and_gradient(p);
            assert!(
                (v - (2.0 * p.x - 3.0 * p.y + 0.5 * p.z)).abs() < 1e-5,
                "{v} at {p}"
            );
            assert!((g - DVec3::new(2.0, -3.0, 0.5)).length() < 1e-5, "{g}");
        }
        let g = vol.node_gradient([0, 2, 4]);
        assert!((g - DVec3::new(2.0, -3.0, 0.5)).length() < 1e-5, "{g}");
    }

    #[test]
    fn bad_volumes_are_refused_naming_the_problem() {
        let l = Lattice::new([2, 2, 2], DVec3::ZERO, DVec3::ONE).unwrap();
        let e = Volume::new(l, Values::U8(vec![0; 7])).unwrap_err();
        assert!(e.to_string().contains("needs 8 values"), "{e}");
        let mut v = vec![0.0f32; 8];
        v[5] = f32::NAN;
        let e = Volume::new(l, Values::F32(v)).unwrap_err();
        assert!(e.to_string().contains("node 5 (x=1, y=0, z=1)"), "{e}");
        assert!(Lattice::new([1, 2, 2], DVec3::ZERO, DVec3::ONE).is_err());
        assert!(Lattice::new([2, 2, 2], DVec3::ZERO, DVec3::new(1.0, 0.0, 1.0)).is_err());
    }
}
