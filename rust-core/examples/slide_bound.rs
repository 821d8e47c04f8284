//! A floor under any exact isovalue update (issue #8's benchmark): between two isovalues,
//! the cells whose marching-cubes case changes must at least be classified again and
//! their new triangles written, whatever bookkeeping a method keeps. This times exactly
//! that and nothing else: the changed cells handed over as a sorted list (found by
//! classifying every cell at both isovalues, not timed), their eight corners read from
//! the volume, the case looked up, each new triangle's three edge keys written, on all
//! threads. No removal of the old triangles, no vertices, no normals, no state: a
//! method that keeps a surface up to date does all of this and more.
//!
//! `cargo run --release -p isobar --example slide_bound -- VOLUME ISO0 ISO1 [REPEATS]`
//!
//! prints the changed cells, the triangles they get at ISO1, and the median and fastest
//! of REPEATS (default 21) timings of the pass. `bench/slider/README.md` (session 42) sets
//! it beside vtkFlyingEdges3D on the benchmark's volumes.
use isobar::io::volume::read_volume;
use isobar::mc::{case_index, case_table, corner_offset, edge_corner_axis, edge_key, VirtualGrid};
use rayon::prelude::*;
use std::path::Path;
use std::time::Instant;

/// Changed cells per task.
const CHUNK: usize = 4096;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let [path, iso0, iso1, rest @ ..] = args.as_slice() else {
        return Err("usage: slide_bound VOLUME ISO0 ISO1 [REPEATS]".into());
    };
    let (iso0, iso1): (f64, f64) = (iso0.parse()?, iso1.parse()?);
    let repeats: usize = rest.first().map_or(Ok(21), |r| r.parse())?;
    if repeats == 0 {
        return Err("REPEATS must be at least 1".into());
    }
    let volume = read_volume(Path::new(path), None, None)?;
    let [nx, ny, nz] = volume.lattice.dims;
    let corners = |x: usize, y: usize, z: usize| -> [f64; 8] {
        std::array::from_fn(|c| {
            let [dx, dy, dz] = corner_offset(c).map(|d| d as usize);
            volume.at(x + dx, y + dy, z + dz) as f64
        })
    };
    // Not timed: which cells change case.
    let changed: Vec<[u32; 3]> = (0..nz - 1)
        .into_par_iter()
        .flat_map_iter(|z| {
            (0..ny - 1).flat_map(move |y| {
                (0..nx - 1).filter_map(move |x| {
                    let v = corners(x, y, z);
                    (case_index(&v, iso0) != case_index(&v, iso1))
                        .then_some([x as u32, y as u32, z as u32])
                })
            })
        })
        .collect();
    let table = case_table();
    // One output list per task, kept from pass to pass as a slider keeps its lists: the
    // first pass's page faults are not counted.
    let mut lists: Vec<Vec<[u64; 3]>> = vec![Vec::new(); changed.len().div_ceil(CHUNK)];
    let pass = |lists: &mut [Vec<[u64; 3]>]| {
        lists
            .par_iter_mut()
            .zip(changed.par_chunks(CHUNK))
            .for_each(|(out, cells)| {
                out.clear();
                for &[x, y, z] in cells {
                    let case = case_index(&corners(x as usize, y as usize, z as usize), iso1);
                    let node = VirtualGrid::key(x, y, z);
                    for t in &table.triangles[case as usize] {
                        out.push(t.map(|e| {
                            let (corner, axis) = edge_corner_axis(e as usize);
                            edge_key(VirtualGrid::corner(node, corner), axis)
                        }));
                    }
                }
            });
    };
    pass(&mut lists);
    let triangles: usize = lists.iter().map(Vec::len).sum();
    let mut ms: Vec<f64> = (0..repeats)
        .map(|_| {
            let t = Instant::now();
            pass(&mut lists);
            let elapsed = t.elapsed().as_secs_f64() * 1e3;
            std::hint::black_box(&lists);
            elapsed
        })
        .collect();
    ms.sort_by(f64::total_cmp);
    println!(
        "changed_cells {} triangles {} median_ms {:.3} min_ms {:.3} threads {}",
        changed.len(),
        triangles,
        ms[ms.len() / 2],
        ms[0],
        rayon::current_num_threads()
    );
    Ok(())
}
