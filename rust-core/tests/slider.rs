//! The slider against from-scratch marching cubes of the same volume, its coherent
//! updates, and its store's refusal of damaged files.

use glam::DVec3;
use isobar::field::grid::{Lattice, Values, Volume};
use isobar::field::ScalarField;
use isobar::mc::{edge_key, VirtualGrid};
use isobar::mesh::Mesh;
use isobar::progress::Progress;
use isobar::slider::lod::APEX;
use isobar::slider::{build_store, full, BuildParams, LodParams, Slider, Store};
use std::collections::HashMap;
use std::path::PathBuf;

fn temp(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("isobar-slider-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir.join(name)
}

struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f64 {
        self.0 = self
            .0
            .wrapping_mul(6364136223846793005)
            .wrapping_add(1442695040888963407);
        (self.0 >> 11) as f64 / (1u64 << 53) as f64
    }
}

/// Two blobs (sum of Gaussians) plus noise, f32: closed surfaces for mid isovalues.
fn blobs(dims: [usize; 3], noise: f64) -> Volume {
    let lattice = Lattice::new(
        dims,
        DVec3::new(-1.0, -0.5, 0.25),
        DVec3::new(0.1, 0.12, 0.09),
    )
    .unwrap();
    let mut rng = Lcg(7);
    let hi = lattice.position([dims[0] - 1, dims[1] - 1, dims[2] - 1]);
    let lo = lattice.origin;
    let c1 = lo + (hi - lo) * DVec3::new(0.35, 0.4, 0.5);
    let c2 = lo + (hi - lo) * DVec3::new(0.65, 0.6, 0.45);
    let r = (hi - lo).min_element() * 0.2;
    let mut v = Vec::new();
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                let p = lattice.position([x, y, z]);
                let f = (-(p - c1).length_squared() / (r * r)).exp()
                    + 0.8 * (-(p - c2).length_squared() / (r * r)).exp()
                    + noise * (rng.next() - 0.5);
                v.push(f as f32);
            }
        }
    }
    Volume::new(lattice, Values::F32(v)).unwrap()
}

/// u8 noise: many ties between node values.
fn ties(dims: [usize; 3]) -> Volume {
    let lattice = Lattice::new(dims, DVec3::ZERO, DVec3::ONE).unwrap();
    let mut rng = Lcg(3);
    let v = (0..lattice.node_count())
        .map(|_| (rng.next() * 12.0) as u8)
        .collect();
    Volume::new(lattice, Values::U8(v)).unwrap()
}

fn store_of(volume: &Volume, name: &str, threshold: f64) -> PathBuf {
    let path = temp(name);
    let params = BuildParams {
        threshold,
        ..BuildParams::default()
    };
    build_store(volume, &path, &params, &mut Progress::none()).unwrap();
    path
}

/// The grid edge key (as `mc` names edges) of a slider edge id.
fn mc_key(lattice: &Lattice, id: u32) -> u64 {
    let (node, axis) = ((id / 3) as usize, (id % 3) as usize);
    let [x, y, z] = lattice.coords(node);
    edge_key(VirtualGrid::key(x as u32, y as u32, z as u32), axis)
}

/// Triangles as edge-key triples, each rotated to start at its smallest key (orientation
/// kept), sorted; plus position and normal per edge key.
type Canon = (Vec<[u64; 3]>, HashMap<u64, ([f32; 3], [f32; 3])>);

fn canon(keys: &[u64], tris: &[[u32; 3]], pos: &[[f32; 3]], nor: &[[f32; 3]]) -> Canon {
    let mut t: Vec<[u64; 3]> = tris
        .iter()
        .map(|t| {
            let k = t.map(|i| keys[i as usize]);
            let m = (0..3).min_by_key(|&i| k[i]).unwrap();
            [k[m], k[(m + 1) % 3], k[(m + 2) % 3]]
        })
        .collect();
    t.sort_unstable();
    let v = keys
        .iter()
        .enumerate()
        .map(|(i, &k)| (k, (pos[i], nor[i])))
        .collect();
    (t, v)
}

fn slider_canon(s: &Slider) -> Canon {
    let lattice = *s.store().lattice();
    let keys: Vec<u64> = s
        .vertex_edges()
        .iter()
        .map(|&e| mc_key(&lattice, e))
        .collect();
    canon(&keys, &s.triangles(), s.positions(), s.normals())
}

/// The reference mesh's canonical form: its vertices are the sorted cut-edge keys.
fn reference_canon(volume: &Volume, iso: f64) -> (Canon, Mesh) {
    let (mesh, keys) = full::extract_keyed(volume, iso, &mut Progress::none()).unwrap();
    let pos: Vec<[f32; 3]> = mesh.positions.iter().map(|p| p.map(|c| c as f32)).collect();
    (canon(&keys, &mesh.triangles, &pos, &mesh.normals), mesh)
}

fn assert_same(slider: &Canon, reference: &Canon, what: &str) {
    assert_eq!(slider.0.len(), reference.0.len(), "{what}: triangle counts");
    assert!(slider.0 == reference.0, "{what}: triangles differ");
    for (k, (p, n)) in &slider.1 {
        let (rp, rn) = reference
            .1
            .get(k)
            .unwrap_or_else(|| panic!("{what}: edge {k}"));
        assert_eq!(p, rp, "{what}: position of edge {k}");
        assert_eq!(n, rn, "{what}: normal of edge {k}");
    }
}

#[test]
fn slider_equals_from_scratch_marching_cubes_for_many_isovalues() {
    for (name, volume, threshold) in [
        ("blobs", blobs([22, 19, 24], 0.05), 0.25),
        ("blobs-t", blobs([22, 19, 24], 0.05), 0.02),
        ("ties", ties([13, 11, 12]), 0.25),
    ] {
        let path = store_of(&volume, &format!("{name}.isoslider"), threshold);
        let mut slider = Slider::open(&path).unwrap();
        assert!(slider.store().level_count() >= 2, "{name}: skip list built");
        let (lo, hi) = volume.range();
        let mut rng = Lcg(11);
        let mut used_levels = 0u64;
        let mut isos: Vec<f64> = (0..25)
            .map(|_| lo as f64 + (hi - lo) as f64 * rng.next())
            .collect();
        // Exact node values, small steps and jumps both ways.
        isos.extend([lo as f64, hi as f64, 5.0, 5.0, 4.0, 0.3, 0.31, 0.305, 0.9]);
        for iso in isos {
            let change = slider.set_isovalue(iso).unwrap();
            used_levels += change.blocks_per_level[1..].iter().sum::<u64>();
            let (reference, mesh) = reference_canon(&volume, iso);
            assert_same(
                &slider_canon(&slider),
                &reference,
                &format!("{name} at {iso}"),
            );
            assert_eq!(slider.triangle_count(), mesh.triangles.len());
        }
        assert!(
            used_levels > 0,
            "{name}: the walks never used the skip list"
        );
    }
}

#[test]
fn slider_vertices_lie_on_edges_at_the_linear_crossing() {
    // Independent of the shared vertex code: recompute t from the volume.
    let volume = blobs([16, 15, 14], 0.0);
    let path = store_of(&volume, "cross.isoslider", 0.25);
    let mut s = Slider::open(&path).unwrap();
    let iso = 0.5;
    s.set_isovalue(iso).unwrap();
    assert!(s.triangle_count() > 100);
    let l = volume.lattice;
    for (i, &e) in s.vertex_edges().iter().enumerate() {
        let (node, axis) = ((e / 3) as usize, (e % 3) as usize);
        let c = l.coords(node);
        let mut up = c;
        up[axis] += 1;
        let (a, b) = (
            volume.at(c[0], c[1], c[2]) as f64,
            volume.at(up[0], up[1], up[2]) as f64,
        );
        assert!((a <= iso) != (b <= iso), "edge {e} is not cut");
        let t = (iso - a) / (b - a);
        let want = l.position(c) + (l.position(up) - l.position(c)) * t;
        let got = DVec3::from_array(s.positions()[i].map(|v| v as f64));
        assert!((got - want).length() < 1e-5, "vertex {i}: {got} vs {want}");
        // Normals point down the field, out of the blob.
        let n = DVec3::from_array(s.normals()[i].map(|v| v as f64));
        assert!((n.length() - 1.0).abs() < 1e-4);
    }
}

#[test]
fn sliding_up_and_back_returns_the_identical_state_and_changes_add_up() {
    let volume = blobs([20, 20, 20], 0.08);
    let path = store_of(&volume, "updown.isoslider", 0.25);
    let mut s = Slider::open(&path).unwrap();
    s.set_isovalue(0.4).unwrap();
    let before = slider_canon(&s);
    let before_raw = raw(&s);
    let cells = s.cells();
    // Small steps up, a jump below everything and back, a big step up and back down.
    for iso in [0.401, 0.405, 0.425, 0.525, 0.4, -4.6, 0.525, 0.825, 0.4] {
        let old = slider_canon(&s);
        let old_keys: Vec<u64> = s
            .vertex_edges()
            .iter()
            .map(|&e| mc_key(s.store().lattice(), e))
            .collect();
        let change = s.set_isovalue(iso).unwrap();
        let new_keys: Vec<u64> = s
            .vertex_edges()
            .iter()
            .map(|&e| mc_key(s.store().lattice(), e))
            .collect();
        // old − removed + added = new, as multisets of edge-key triangles.
        let key_tri = |keys: &[u64], t: &[u32; 3]| {
            let k = t.map(|i| keys[i as usize]);
            let m = (0..3).min_by_key(|&i| k[i]).unwrap();
            [k[m], k[(m + 1) % 3], k[(m + 2) % 3]]
        };
        let mut count: HashMap<[u64; 3], i64> = HashMap::new();
        for t in &old.0 {
            *count.entry(*t).or_default() += 1;
        }
        for t in &change.removed_triangles {
            *count.entry(key_tri(&old_keys, t)).or_default() -= 1;
        }
        for t in &change.added_triangles {
            *count.entry(key_tri(&new_keys, t)).or_default() += 1;
        }
        let mut expect: Vec<[u64; 3]> = count
            .into_iter()
            .flat_map(|(t, n)| {
                assert!(n >= 0, "a removed triangle was not there");
                std::iter::repeat_n(t, n as usize)
            })
            .collect();
        expect.sort_unstable();
        assert!(
            expect == slider_canon(&s).0,
            "change does not add up at {iso}"
        );
        for &(from, to) in &change.moved_vertices {
            assert_eq!(old_keys[from as usize], new_keys[to as usize]);
        }
    }
    let after = slider_canon(&s);
    assert_eq!(s.cells(), cells);
    assert_same(&after, &before, "back at 0.4");
    assert_eq!(after.0, before.0);
    // Not only the same surface: the same arrays in the same order, as hosts read them.
    assert!(
        raw(&s) == before_raw,
        "back at 0.4: arrays in another order"
    );
    assert_eq!(s.stats().updates, 10);
}

/// What a host reads, as it reads it: each vertex's edge, V and I, in order.
type Raw = (Vec<u32>, Vec<[f32; 3]>, Vec<[u32; 3]>);

fn raw(s: &Slider) -> Raw {
    (
        s.vertex_edges().to_vec(),
        s.positions().to_vec(),
        s.triangles(),
    )
}

/// The volume of the Blender add-on's slider test (`tests/blender/test_volume_slider.py`,
/// `_volume`): two overlapping Gaussians on an n³ lattice over [-1, 1]³, f32, stored
/// as an `.npy` is read (unit spacing, origin 0, x fastest).
fn blender_blobs(n: usize) -> Volume {
    let x: Vec<f32> = (0..n)
        .map(|i| (-1.0 + 2.0 * i as f64 / (n - 1) as f64) as f32)
        .collect();
    let mut v = Vec::with_capacity(n * n * n);
    for &z in &x {
        for &y in &x {
            for &xx in &x {
                let blob = |c: f32| (-6.0 * ((xx - c).powi(2) + y * y + z * z)).exp();
                v.push(blob(0.35) + blob(-0.35));
            }
        }
    }
    let lattice = Lattice::new([n; 3], DVec3::ZERO, DVec3::ONE).unwrap();
    Volume::new(lattice, Values::F32(v)).unwrap()
}

/// Hosts compare what they show raw: the Blender test slides its object away and back
/// and wants the very arrays it showed before, triangle order included (a re-emission
/// order that depends on the path, e.g. first occurrence instead of ascending cell id,
/// keeps the canonical surface but fails there). The same volume, store parameters and
/// path (from the middle of the value range, isovalues in f32 as Blender keeps them).
#[test]
fn sliding_away_and_back_gives_a_host_the_identical_arrays_in_order() {
    let volume = blender_blobs(28);
    let path = store_of(
        &volume,
        "blender-path.isoslider",
        BuildParams::default().threshold,
    );
    let mut s = Slider::open(&path).unwrap();
    let (lo, hi) = s.store().value_range();
    let mid = (0.5 * (lo as f64 + hi as f64)) as f32;
    s.set_isovalue(mid as f64).unwrap();
    let mut shown: Vec<(f32, Raw)> = Vec::new();
    for iso in [0.3f32, 0.31, 0.5, 0.9, 0.2, 0.3] {
        s.set_isovalue(iso as f64).unwrap();
        let now = raw(&s);
        assert!(!now.2.is_empty(), "{iso}: a surface");
        if let Some((_, before)) = shown.iter().find(|(v, _)| *v == iso) {
            assert_eq!(now.0, before.0, "back at {iso}: vertex edges in order");
            assert_eq!(now.1, before.1, "back at {iso}: positions in order");
            assert!(now.2 == before.2, "back at {iso}: triangles in order");
        }
        shown.push((iso, now));
    }
}

#[test]
fn closed_surfaces_are_watertight() {
    let volume = blobs([24, 24, 24], 0.0);
    let path = store_of(&volume, "closed.isoslider", 0.25);
    let mut s = Slider::open(&path).unwrap();
    for iso in [0.2, 0.5, 0.7, 0.35] {
        s.set_isovalue(iso).unwrap();
        let mesh = Mesh {
            positions: s.positions().iter().map(|p| p.map(|c| c as f64)).collect(),
            triangles: s.triangles(),
            ..Mesh::default()
        };
        assert!(mesh.triangles.len() > 200);
        assert!(
            mesh.topology().is_watertight_oriented(),
            "{iso}: {:?}",
            mesh.topology()
        );
        // Normals point out of the region above the isovalue, like the triangles.
        assert!(mesh.signed_volume() != 0.0);
    }
}

#[test]
fn same_store_bytes_for_any_thread_count() {
    let volume = blobs([14, 13, 12], 0.1);
    let a = store_of(&volume, "det-a.isoslider", 0.25);
    let pool = rayon::ThreadPoolBuilder::new()
        .num_threads(1)
        .build()
        .unwrap();
    let b = temp("det-b.isoslider");
    pool.install(|| build_store(&volume, &b, &BuildParams::default(), &mut Progress::none()))
        .unwrap();
    assert_eq!(std::fs::read(&a).unwrap(), std::fs::read(&b).unwrap());
}

/// Large changes re-triangulate their cells and interpolate their edges on several
/// threads: the arrays a host reads are the same, in the same order, as on one thread,
/// and the surface is marching cubes' at every step.
#[test]
fn large_updates_give_the_same_arrays_on_any_thread_count() {
    let volume = blobs([64, 60, 56], 0.3);
    let path = store_of(
        &volume,
        "threads.isoslider",
        BuildParams::default().threshold,
    );
    let (lo, hi) = volume.range();
    let isos: Vec<f64> = [0.45, 0.5, 0.3, 0.9, 0.31, 0.0, 0.45]
        .iter()
        .map(|f| lo as f64 + f * (hi - lo) as f64)
        .collect();
    let slide = |threads: usize| {
        let pool = rayon::ThreadPoolBuilder::new()
            .num_threads(threads)
            .build()
            .unwrap();
        pool.install(|| {
            let mut s = Slider::open(&path).unwrap();
            let (mut most, mut most_edges) = (0, 0);
            let steps: Vec<(Raw, Canon)> = isos
                .iter()
                .map(|&iso| {
                    let c = s.set_isovalue(iso).unwrap();
                    most = most.max(c.added_triangles.len() + c.removed_triangles.len());
                    most_edges = most_edges.max(c.edges_added);
                    (raw(&s), slider_canon(&s))
                })
                .collect();
            (steps, most, most_edges)
        })
    };
    let (one, most, most_edges) = slide(1);
    let (four, _, _) = slide(4);
    // A cell adds and removes at most 5 triangles each: this many changed triangles
    // means over 4,000 changed cells, past the size where the update goes parallel.
    assert!(
        most > 40_000,
        "changes too small to run in parallel: {most}"
    );
    // Over 16,384 added edges (and more dirty cells, four around each) are computed in
    // several batches of 8,192.
    assert!(
        most_edges > 16_384,
        "changes too small for several batches: {most_edges}"
    );
    for ((iso, (a, ca)), (b, _)) in isos.iter().zip(&one).zip(&four) {
        assert!(a == b, "at {iso}: arrays differ between 1 and 4 threads");
        assert_same(ca, &reference_canon(&volume, *iso).0, &format!("at {iso}"));
    }
}
/// After a jump from a large surface to a small one, the slider holds memory for the
/// small one, not what the large one needed (its lists and bricks are given back).
#[test]
fn held_memory_follows_the_surface_after_a_jump() {
    let volume = blobs([128, 120, 112], 0.3);
    let path = store_of(&volume, "held.isoslider", BuildParams::default().threshold);
    let (lo, hi) = volume.range();
    let at = |f: f64| lo as f64 + f * (hi - lo) as f64;
    // What a host does after each update: read the full arrays.
    let show = |s: &mut Slider, iso: f64| {
        s.set_isovalue(iso).unwrap();
        assert!(!s.positions().is_empty() && !s.triangle_array().is_empty());
        s.held_bytes()
    };
    // The jump itself needs lists as long as the large surface; the small steps after
    // it need short ones.
    let mut jumped = Slider::open(&path).unwrap();
    let large = show(&mut jumped, at(0.45));
    for f in [0.9, 0.901, 0.9] {
        show(&mut jumped, at(f));
    }
    let after = jumped.held_bytes();
    let mut direct = Slider::open(&path).unwrap();
    for f in [0.9, 0.901, 0.9] {
        show(&mut direct, at(f));
    }
    let small = direct.held_bytes();
    assert!(
        jumped.triangles() == direct.triangles(),
        "same surface either way"
    );
    // Scratch lists are cut to at most four times what they use (none below 64 KiB:
    // about 20 lists), the surface's own lists to a quarter more, bricks to a quarter
    // more than those in use.
    let bound = 4 * small + (2 << 20);
    assert!(
        large > 2 * bound,
        "the large surface should need far more: {large} vs small {small}"
    );
    assert!(
        after <= bound,
        "after the jump {after} bytes held; the small surface alone holds {small} \
         (large {large})"
    );
}

#[test]
fn damaged_or_foreign_stores_are_refused_clearly() {
    let volume = blobs([10, 9, 8], 0.1);
    let path = store_of(&volume, "good.isoslider", 0.25);
    let good = std::fs::read(&path).unwrap();
    Store::open(&path).unwrap().verify().unwrap();
    let bad = temp("bad.isoslider");
    // Opening checks sizes and tables; the data is checked on first touch, or whole by
    // `verify`.
    let refuse = |bytes: &[u8], want: &str| {
        std::fs::write(&bad, bytes).unwrap();
        let e = Store::open(&bad)
            .and_then(|s| s.verify())
            .err()
            .unwrap_or_else(|| panic!("accepted ({want})"))
            .to_string();
        assert!(e.contains("bad.isoslider"), "{e}");
        assert!(e.contains(want), "wanted '{want}': {e}");
    };
    // Truncated anywhere: refused at once, by `open` alone.
    for cut in [
        0,
        5,
        11,
        60,
        150,
        good.len() / 3,
        good.len() / 2,
        good.len() - 8,
        good.len() - 1,
    ] {
        std::fs::write(&bad, &good[..cut]).unwrap();
        let e = Store::open(&bad)
            .err()
            .unwrap_or_else(|| panic!("cut {cut} accepted"))
            .to_string();
        let want = if cut < 8 { "magic" } else { "truncated" };
        assert!(
            e.contains("bad.isoslider") && e.contains(want),
            "cut {cut}: wanted '{want}': {e}"
        );
    }
    refuse(&good[..good.len() / 2], "truncated");
    // Corrupted: one flipped bit in a section, in the header, in the directory.
    for at in [good.len() / 2, good.len() - 3, 200] {
        let mut b = good.clone();
        b[at] ^= 0x10;
        refuse(&b, "corrupt");
    }
    let mut b = good.clone();
    b[20] ^= 1;
    refuse(&b, "checksum");
    // Another version is refused, not misread.
    let mut b = good.clone();
    b[8..12].copy_from_slice(&1u32.to_le_bytes());
    refuse(&b, "version 1");
    let mut b = good;
    b[..8].copy_from_slice(b"NOTASTOR");
    refuse(&b, "magic");
}

/// A corrupt chunk is refused by the slider when it first reads it, not used: a byte of
/// the body flipped (one about every chunk, at varying offsets inside it) makes some
/// isovalue sweep fail with a "corrupt" error naming the file, or `verify` fail, never
/// a panic or a silently different surface.
/// A store cut short by another process while a slider has it mapped: the next update
/// is an error naming the file, not a SIGBUS when the walk reads a page past the end.
#[test]
fn a_store_truncated_while_open_is_refused_at_the_next_update() {
    let volume = blobs([30, 29, 28], 0.1);
    let path = store_of(&volume, "cut-while-open.isoslider", 0.25);
    let mut s = Slider::open(&path).unwrap();
    s.set_isovalue(0.3).unwrap();
    let len = std::fs::metadata(&path).unwrap().len();
    let file = std::fs::OpenOptions::new().write(true).open(&path).unwrap();
    file.set_len(len / 3).unwrap();
    for iso in [0.9, -0.5, 0.31] {
        let e = s.set_isovalue(iso).unwrap_err().to_string();
        assert!(
            e.contains("cut-while-open.isoslider")
                && e.contains("truncated to")
                && e.contains("while open"),
            "{e}"
        );
    }
    // The slider keeps the surface it had.
    assert_eq!(s.isovalue(), 0.3);
}

#[test]
fn corrupt_chunks_are_refused_when_first_read() {
    let volume = blobs([30, 29, 28], 0.1);
    let path = store_of(&volume, "lazy.isoslider", 0.25);
    let good = std::fs::read(&path).unwrap();
    let header = {
        let s = Store::open(&path).unwrap();
        s.verify().unwrap();
        // The first section starts after the header: find it from the directory.
        u64::from_le_bytes(good[104 + 8..104 + 16].try_into().unwrap()) as usize
    };
    let sweep = [0.2, 0.45, 0.3, 0.9, -0.5, 0.6];
    let mut reference = Slider::open(&path).unwrap();
    let expected: Vec<Canon> = sweep
        .iter()
        .map(|&iso| {
            reference.set_isovalue(iso).unwrap();
            slider_canon(&reference)
        })
        .collect();
    let bad = temp("lazy-bad.isoslider");
    let mut refused_at_use = 0;
    for at in (header..good.len()).step_by(4099) {
        let mut b = good.clone();
        b[at] ^= 0x04;
        std::fs::write(&bad, &b).unwrap();
        let mut s = match Slider::open(&bad) {
            Ok(s) => s,
            Err(e) => {
                // Refused at open (the chunk table or the level tables).
                let e = e.to_string();
                assert!(e.contains("lazy-bad.isoslider"), "byte {at}: {e}");
                continue;
            }
        };
        // Every isovalue is either the reference surface or refused as corrupt, also
        // after an earlier refusal (the slider must not be left half updated).
        let mut failed = None;
        for (iso, want) in sweep.iter().zip(&expected) {
            match s.set_isovalue(*iso) {
                Ok(_) => assert!(slider_canon(&s) == *want, "byte {at}: a different surface"),
                Err(e) => {
                    let e = e.to_string();
                    assert!(e.contains("corrupt"), "byte {at}, iso {iso}: {e}");
                    failed.get_or_insert(e);
                }
            }
        }
        match failed {
            Some(e) => {
                assert!(
                    e.contains("corrupt") && e.contains("lazy-bad.isoslider"),
                    "{e}"
                );
                refused_at_use += 1;
            }
            None => {
                let e = s.store().verify().unwrap_err().to_string();
                assert!(e.contains("corrupt"), "byte {at}: {e}");
            }
        }
    }
    assert!(refused_at_use > 0);
}

#[test]
fn over_budget_volumes_are_refused_before_work() {
    let volume = blobs([10, 10, 10], 0.0);
    let params = BuildParams {
        memory_budget: 1000,
        ..BuildParams::default()
    };
    let e = build_store(
        &volume,
        &temp("x.isoslider"),
        &params,
        &mut Progress::none(),
    )
    .unwrap_err()
    .to_string();
    assert!(e.contains("memory budget"), "{e}");
    assert!(!temp("x.isoslider").exists());
}

/// Files in `dir` (no temporaries may be left behind).
fn files_in(dir: &std::path::Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn external_memory_builds_write_the_in_memory_store() {
    // Nested spheres in 64×60×56 nodes: 215,040 nodes, 6.2 MB for an in-memory build; a
    // budget of 4 MiB sorts them on disk (one run: several runs are the unit test
    // `stores_sorted_in_runs_on_disk_are_the_in_memory_store`) and spools the levels.
    let volume = sphere([64, 60, 56]);
    let dir = std::env::temp_dir().join(format!("isobar-external-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let build = |name: &str, memory_budget: u64| {
        let params = BuildParams {
            memory_budget,
            ..BuildParams::default()
        };
        let path = dir.join(name);
        build_store(&volume, &path, &params, &mut Progress::none()).map(|s| (path, s))
    };
    let (whole, in_memory) = build("whole.isoslider", 64 << 20).unwrap();
    let (spooled, external) = build("spooled.isoslider", 4 << 20).unwrap();
    assert!(in_memory.level_blocks.len() >= 3, "{in_memory:?}");
    assert_eq!(
        std::fs::read(&whole).unwrap(),
        std::fs::read(&spooled).unwrap(),
        "the external-memory build wrote a different store"
    );
    assert_eq!(in_memory.level_edges, external.level_edges);
    assert_eq!((in_memory.sorted_runs, external.sorted_runs), (0, 1));
    // The store is usable: the slider's surface equals marching cubes of the volume.
    let mut slider = Slider::open(&spooled).unwrap();
    slider.set_isovalue(-9.5).unwrap();
    assert!(slider.triangle_count() > 500);
    assert_same(
        &slider_canon(&slider),
        &reference_canon(&volume, -9.5).0,
        "external-memory store at -9.5",
    );
    // Too small a budget even for sorting on disk, and one too small for the levels'
    // open blocks: refused, and nothing left in the folder either way.
    for budget in [20_000, 200_000] {
        let e = build("refused.isoslider", budget).unwrap_err().to_string();
        assert!(e.contains("memory budget"), "{budget}: {e}");
        // Where the open blocks crossed the budget is not their peak: the message says so.
        let levels = e.contains("open blocks") && e.contains("the whole build may need more");
        assert_eq!(levels, budget == 200_000, "{budget}: {e}");
    }
    assert_eq!(files_in(&dir), ["spooled.isoslider", "whole.isoslider"]);
    std::fs::remove_dir_all(&dir).unwrap();
}

// ---- Level of detail ----

/// f32 volume of `f` at the nodes of a unit-spaced lattice of `dims` nodes.
fn analytic(dims: [usize; 3], f: impl Fn(DVec3) -> f64) -> Volume {
    let lattice = Lattice::new(dims, DVec3::new(0.5, -1.0, 2.0), DVec3::ONE).unwrap();
    let mut v = Vec::with_capacity(lattice.node_count());
    for z in 0..dims[2] {
        for y in 0..dims[1] {
            for x in 0..dims[0] {
                v.push(f(lattice.position([x, y, z])) as f32);
            }
        }
    }
    Volume::new(lattice, Values::F32(v)).unwrap()
}

/// Minus the distance to a centre: closed spheres for isovalues −radius.
fn sphere(dims: [usize; 3]) -> Volume {
    let lattice = Lattice::new(dims, DVec3::new(0.5, -1.0, 2.0), DVec3::ONE).unwrap();
    let c = lattice.position(dims.map(|d| d / 2)) + DVec3::new(0.3, 0.17, -0.21);
    analytic(dims, move |p| -(p - c).length())
}

/// Minus the distance to a circle of radius 11 in a tilted plane: closed tori.
fn torus(dims: [usize; 3]) -> Volume {
    let lattice = Lattice::new(dims, DVec3::new(0.5, -1.0, 2.0), DVec3::ONE).unwrap();
    let c = lattice.position(dims.map(|d| d / 2)) + DVec3::new(0.21, -0.3, 0.11);
    let n = DVec3::new(0.3, 0.2, 1.0).normalize();
    analytic(dims, move |p| {
        let d = p - c;
        let h = d.dot(n);
        let r = (d - n * h).length();
        -((r - 11.0).powi(2) + h * h).sqrt()
    })
}

/// LOD cases: name, volume, closed-surface isovalues.
fn lod_volumes() -> Vec<(&'static str, Volume, Vec<f64>)> {
    vec![
        ("sphere", sphere([40, 38, 42]), vec![-15.0, -9.3, -4.2]),
        ("torus", torus([40, 40, 40]), vec![-3.0, -5.5]),
        ("blobs", blobs([34, 30, 36], 0.02), vec![0.35, 0.6]),
    ]
}

fn lod_slider(volume: &Volume, name: &str) -> Slider {
    Slider::open(&store_of(volume, &format!("lod-{name}.isoslider"), 0.25)).unwrap()
}

fn lod_params(error_bound: f64) -> LodParams {
    LodParams {
        error_bound,
        ..LodParams::default()
    }
}

#[test]
fn lod_meshes_of_closed_surfaces_are_watertight_and_oriented() {
    let mut transitions = 0;
    for (name, volume, isos) in lod_volumes() {
        let mut s = lod_slider(&volume, name);
        for iso in isos {
            s.set_isovalue(iso).unwrap();
            for bound in [0.001, 0.01, 0.05] {
                s.set_lod(lod_params(bound)).unwrap();
                let lod = s.lod_mesh().unwrap();
                let mesh = lod.mesh();
                let what = format!("{name} at {iso}, bound {bound}");
                assert!(mesh.triangles.len() > 50, "{what}");
                let topo = mesh.topology();
                assert!(topo.is_watertight_oriented(), "{what}: {topo:?}");
                // Same components and orientation (sign of the volume) as the exact surface.
                let exact = Mesh {
                    positions: s.positions().iter().map(|p| p.map(f64::from)).collect(),
                    triangles: s.triangles(),
                    ..Mesh::default()
                };
                assert_eq!(mesh.components(), exact.components(), "{what}");
                let (v, w) = (mesh.signed_volume(), exact.signed_volume());
                // Enclosed volume close to the exact one (8³ cells on a radius-9 sphere
                // at 5 % lose a few per cent).
                let tol = if bound < 0.05 { 0.05 } else { 0.15 };
                assert!(
                    v * w > 0.0 && (v / w - 1.0).abs() < tol,
                    "{what}: {v} vs {w}"
                );
                if bound >= 0.05 {
                    assert!(lod.cells_per_level[1..].iter().sum::<u64>() > 0, "{what}");
                }
                transitions += lod.transition_cells;
            }
        }
    }
    assert!(transitions > 0, "no cell met a finer one");
}

#[test]
fn lod_vertices_and_merged_cells_keep_the_error_bound() {
    for (name, volume, isos) in lod_volumes() {
        let mut s = lod_slider(&volume, name);
        let (lo, hi) = volume.range();
        let range = (hi - lo) as f64;
        let l = volume.lattice;
        for iso in isos {
            s.set_isovalue(iso).unwrap();
            let (exact, keys) = full::extract_keyed(&volume, iso, &mut Progress::none()).unwrap();
            for bound in [0.001, 0.01] {
                s.set_lod(lod_params(bound)).unwrap();
                let lod = s.lod_mesh().unwrap();
                let what = format!("{name} at {iso}, bound {bound}");
                // Every vertex: the trilinear field there is within the bound of the
                // isovalue, relative to the value range (f32 positions: 1e-5 slack) ...
                for p in &lod.positions {
                    let f = volume.value(DVec3::from_array(p.map(f64::from)));
                    assert!(
                        (f - iso).abs() <= (bound + 1e-5) * range,
                        "{what}: vertex {p:?} has value {f}"
                    );
                }
                // ... and, unless it is a fan apex, is the exact mesh's vertex of the same
                // lattice edge.
                for (i, &e) in lod.vertex_edges.iter().enumerate() {
                    if e == APEX {
                        continue;
                    }
                    let k = keys.binary_search(&mc_key(&l, e)).expect("an exact edge");
                    let want = exact.positions[k].map(|c| c as f32);
                    assert_eq!(lod.positions[i], want, "{what}: edge {e}");
                }
                // Every merged cell: each deleted sample within Δ of the corners'
                // interpolant, at most one crossing on every line of samples.
                for c in lod.cells.iter().filter(|c| c.level > 0) {
                    let n = 1usize << c.level;
                    let o = c.origin.map(|v| v as usize);
                    let at =
                        |d: [usize; 3]| volume.at(o[0] + d[0], o[1] + d[1], o[2] + d[2]) as f64;
                    let corners: [f64; 8] =
                        std::array::from_fn(|k| at([k & 1, k >> 1 & 1, k >> 2 & 1].map(|b| b * n)));
                    for z in 0..=n {
                        for y in 0..=n {
                            for x in 0..=n {
                                let t = [x, y, z].map(|v| v as f64 / n as f64);
                                let mut interp = 0.0;
                                for (k, v) in corners.iter().enumerate() {
                                    let w: f64 = (0..3)
                                        .map(|a| if k >> a & 1 == 1 { t[a] } else { 1.0 - t[a] })
                                        .product();
                                    interp += w * v;
                                }
                                assert!(
                                    (interp - at([x, y, z])).abs() <= bound * range * (1.0 + 1e-9),
                                    "{what}: cell {c:?} sample {x},{y},{z}"
                                );
                            }
                        }
                    }
                    for a in 0..3 {
                        for i in 0..=n {
                            for j in 0..=n {
                                let changes = (0..n)
                                    .filter(|&k| {
                                        let mut p = [0; 3];
                                        p[(a + 1) % 3] = i;
                                        p[(a + 2) % 3] = j;
                                        p[a] = k;
                                        let mut q = p;
                                        q[a] += 1;
                                        (at(p) > iso) != (at(q) > iso)
                                    })
                                    .count();
                                assert!(changes <= 1, "{what}: cell {c:?} axis {a} line {i},{j}");
                            }
                        }
                    }
                }
                // Distance to the exact surface: within one lattice cell.
                let d = isobar::mesh::hausdorff::hausdorff(&lod.mesh(), &exact, 2.0);
                assert!(d < l.spacing.max_element(), "{what}: Hausdorff {d}");
            }
        }
    }
}

#[test]
fn lod_reduces_the_triangles_of_a_smooth_surface() {
    let volume = sphere([48, 48, 48]);
    let mut s = lod_slider(&volume, "reduce");
    s.set_isovalue(-19.0).unwrap();
    let exact = s.triangle_count();
    let mut ratios = Vec::new();
    for bound in [0.001, 0.003, 0.01, 0.03] {
        s.set_lod(lod_params(bound)).unwrap();
        let lod = s.lod_mesh().unwrap();
        let ratio = lod.triangles.len() as f64 / exact as f64;
        eprintln!(
            "sphere r=19 in 48³: exact {exact} triangles, LOD bound {bound}: {} ({ratio:.3}), cells per level {:?}, {} transition cells, {} splits, {:.2} ms",
            lod.triangles.len(),
            lod.cells_per_level,
            lod.transition_cells,
            lod.splits,
            lod.seconds * 1e3
        );
        assert!(lod.mesh().topology().is_watertight_oriented());
        ratios.push(ratio);
    }
    // A distance field curves by 1/r: at r = 19 a level-1 block deviates from its
    // interpolant by ~0.13 % of the range, so 0.1 % merges nothing here and 1 % merges
    // up to level 2.
    assert!(ratios[0] <= 1.0);
    assert!(ratios.windows(2).all(|w| w[1] <= w[0]), "{ratios:?}");
    assert!(ratios[2] < 0.6, "{ratios:?}");
}

#[test]
fn lod_never_has_more_triangles_than_the_exact_mesh() {
    // Small bounds merge a few cells among unmerged ones; those become transition cells
    // whose fans drew more triangles than the exact cells they replaced (sphere r=15 in
    // 48³ at 0.0015: 8,798 against 8,492 before the fix).
    let mut cases = lod_volumes();
    cases.push((
        "sphere48",
        sphere([48, 48, 48]),
        vec![-19.0, -15.0, -9.3, -4.2],
    ));
    let mut merged = 0;
    for (name, volume, isos) in cases {
        let mut s = lod_slider(&volume, &format!("{name}-count"));
        for iso in isos {
            s.set_isovalue(iso).unwrap();
            let exact = s.triangle_count();
            for bound in [0.0005, 0.001, 0.0015, 0.002, 0.003, 0.005, 0.01, 0.02, 0.05] {
                s.set_lod(lod_params(bound)).unwrap();
                let lod = s.lod_mesh().unwrap();
                let what = format!("{name} at {iso}, bound {bound}");
                assert!(
                    lod.triangles.len() <= exact,
                    "{what}: {} LOD triangles, {exact} exact",
                    lod.triangles.len()
                );
                let topo = lod.mesh().topology();
                assert!(topo.is_watertight_oriented(), "{what}: {topo:?}");
                merged += lod.cells_per_level[1..].iter().sum::<u64>();
            }
        }
    }
    assert!(merged > 0, "nothing merged: the comparison tested nothing");
}

#[test]
fn lod_with_bound_zero_is_the_exact_mesh() {
    for (name, volume, isos) in lod_volumes() {
        let mut s = lod_slider(&volume, &format!("{name}-zero"));
        s.set_lod(lod_params(0.0)).unwrap();
        for iso in isos.into_iter().chain([0.5]) {
            s.set_isovalue(iso).unwrap();
            let lod = s.lod_mesh().unwrap();
            assert!(lod.cells_per_level[1..].iter().all(|&n| n == 0));
            let l = *s.store().lattice();
            let keys: Vec<u64> = lod.vertex_edges.iter().map(|&e| mc_key(&l, e)).collect();
            let got = canon(&keys, &lod.triangles, &lod.positions, &lod.normals);
            let (reference, _) = reference_canon(&volume, iso);
            assert_same(&got, &reference, &format!("{name} at {iso}"));
            assert_eq!(got.1.len(), reference.1.len());
        }
    }
}

#[test]
fn a_store_holds_only_the_volume_it_was_built_from() {
    let volume = blobs([11, 9, 7], 0.05);
    let store = Store::open(&store_of(&volume, "holds.isoslider", 0.25)).unwrap();
    assert!(store.holds(&volume).unwrap());
    let Values::F32(v) = &volume.values else {
        unreachable!()
    };
    // One value changed by one unit in the last place, the last node's.
    let mut changed = v.clone();
    let last = changed.len() - 1;
    changed[last] = f32::from_bits(changed[last].to_bits() + 1);
    let other = Volume::new(volume.lattice, Values::F32(changed)).unwrap();
    assert!(!store.holds(&other).unwrap());
    // Same values on another lattice (moved origin), or in another type.
    let mut moved = volume.lattice;
    moved.origin.x += 1e-9;
    assert!(!store
        .holds(&Volume::new(moved, volume.values.clone()).unwrap())
        .unwrap());
    let as_u8 = v.iter().map(|&x| (x * 100.0) as u8).collect();
    assert!(!store
        .holds(&Volume::new(volume.lattice, Values::U8(as_u8)).unwrap())
        .unwrap());
}

/// The slider reads the store's values only around the surface: a small sphere in a
/// corner of a large volume brings a small part of them into memory, in each value
/// type, and the surface is marching cubes' all the same.
#[test]
fn values_are_read_only_around_the_surface() {
    let dims = [128, 64, 64];
    let lattice = Lattice::new(dims, DVec3::ZERO, DVec3::ONE).unwrap();
    let distance = |i: usize| {
        let [x, y, z] = lattice.coords(i).map(|c| c as f64);
        ((x - 12.0).powi(2) + (y - 11.0).powi(2) + (z - 10.0).powi(2)).sqrt()
    };
    let n = lattice.node_count();
    for values in [
        Values::F32((0..n).map(|i| distance(i) as f32).collect()),
        Values::U16((0..n).map(|i| (distance(i) * 100.0) as u16).collect()),
        Values::U8(
            (0..n)
                .map(|i| (distance(i) * 2.0).min(255.0) as u8)
                .collect(),
        ),
    ] {
        let scale = match values {
            Values::F32(_) => 1.0,
            Values::U16(_) => 100.0,
            Values::U8(_) => 2.0,
        };
        let what = format!("{:?}", values.value_type());
        let volume = Volume::new(lattice, values).unwrap();
        let path = store_of(&volume, "around.isoslider", 0.25);
        let mut slider = Slider::open(&path).unwrap();
        assert_eq!(slider.store().values_held(), 0, "{what}: read at open");
        let iso = 6.3 * scale;
        slider.set_isovalue(iso).unwrap();
        assert_same(
            &slider_canon(&slider),
            &reference_canon(&volume, iso).0,
            &what,
        );
        let held = slider.store().values_held();
        let all = n * volume.values.value_type().size();
        // What the surface reads (its edges' nodes and their neighbours, within 10 nodes
        // of the centre) lies in a box of 21 nodes a side, 1/57 of the volume; the 4-KiB
        // bricks around it hold 1/27 (f32) to 1/13 (u8) of the values.
        assert!(
            held > 0 && held * 10 < all,
            "{what}: {held} bytes of values read for a surface in a corner of {all}"
        );
    }
}
