// Crack filling, the paper's Algorithm 3 (appended to sph.wgsl and level.wgsl, whose
// `level` uniform gives the grid, the isovalue and the face count): one invocation per
// transition face walks the face's quads as `adaptive::cracks` does, looks each quad's
// nine fine-side signs up in the generated pattern table (`adaptive::crack_table`,
// uploaded word for word) and maps the pattern's face points to the fine level's E.
// `count_fills` writes each face's triangle count, the host scans them (scan.wgsl) and
// `emit_fills` writes the triangles at the scanned offsets: the CPU's order, face by face.
//
// The fine level's arrays are level.wgsl's own buffers as its kernels left them: `cells`
// (sorted coarse cells), `values` (node values) and `bisect_in` (E: key words, end
// values). So each pass handles one fine level, the faces whose coarse side is
// `fine.coarse`; the host runs it for level 2 and for level 3.

struct Fine {
    coarse: u32,    // the coarse side's level: 1 (fine level 2) or 2 (fine level 3)
    cells_len: u32,
    edges_len: u32,
    pad: u32,
}

@group(0) @binding(14) var<uniform> fine: Fine;
@group(0) @binding(15) var<storage, read> faces: array<vec2<u32>>;       // (lower cell, axis)
@group(0) @binding(16) var<storage, read> cell_levels: array<u32>;
@group(0) @binding(20) var<storage, read> patterns: array<u32>;          // 512 rows of ROW
@group(0) @binding(21) var<storage, read_write> fill_counts: array<u32>;
@group(0) @binding(22) var<storage, read_write> fills: array<vec4<u32>>; // (level, 3 E indices)

const ROW: u32 = 37u;
// An index that was not found: the host turns it into an error (the CPU's `expect`).
const MISSING: u32 = 0xFFFFFFFFu;

// Slot of coarse cell `cell` among the cells of the fine level, or MISSING.
fn fine_slot(cell: u32) -> u32 {
    var lo = 0u;
    var hi = fine.cells_len;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if cells[mid] < cell {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    if lo < fine.cells_len && cells[lo] == cell {
        return lo;
    }
    return MISSING;
}

// Keys are (low word, high word) of a u64.
fn key_less(a: vec2<u32>, b: vec2<u32>) -> bool {
    return a.y < b.y || (a.y == b.y && a.x < b.x);
}

// Index in E of the fine level of the edge `key`, or MISSING.
fn fine_edge(key: vec2<u32>) -> u32 {
    var lo = 0u;
    var hi = fine.edges_len;
    while lo < hi {
        let mid = (lo + hi) / 2u;
        if key_less(bisect_in[mid].xy, key) {
            lo = mid + 1u;
        } else {
            hi = mid;
        }
    }
    if lo < fine.edges_len && all(bisect_in[lo].xy == key) {
        return lo;
    }
    return MISSING;
}

// As `LevelArrays::value_at`: the value at finest node `node` of the fine cell at `c`.
fn fine_value(k: u32, slot: u32, c: vec3<u32>, node: vec3<u32>) -> f32 {
    let n = k + 1u;
    let l = (node - c * 4u) / (4u / k);
    return values[slot * n * n * n + l.x + n * (l.y + n * l.z)];
}

// The level of face `id`'s coarse side (the lower of its two cells' levels).
fn coarse_side(id: u32) -> u32 {
    let face = faces[id];
    var uc = coarse_coords(face.x);
    uc[face.y] += 1u;
    let upper = uc.x + level.cells_x * (uc.y + level.cells_y * uc.z);
    return min(cell_levels[face.x], cell_levels[upper]);
}

// Walks face `id`: its fill triangle count, and when `write` the triangles from `first`.
fn walk_face(id: u32, write: bool, first: u32) -> u32 {
    let face = faces[id];
    let a = face.y;
    let u = (a + 1u) % 3u;
    let v = (a + 2u) % 3u;
    let lc = coarse_coords(face.x);
    var uc = lc;
    uc[a] += 1u;
    let upper = uc.x + level.cells_x * (uc.y + level.cells_y * uc.z);
    // The table is wound for a normal along +a, right when the coarse cell is the lower.
    var coarse = cell_levels[upper];
    var fine_cell = face.x;
    var flip = true;
    if cell_levels[face.x] < coarse {
        coarse = cell_levels[face.x];
        fine_cell = upper;
        flip = false;
    }
    let k = 1u << coarse; // sub-cells per axis of the fine level, coarse + 1
    let slot = fine_slot(fine_cell);
    if slot == MISSING {
        if write {
            fills[first] = vec4<u32>(MISSING);
        }
        return 1u;
    }
    let fc = coarse_coords(fine_cell);
    let quads = 1u << (coarse - 1u);
    let quad = 4u / quads; // quad side in finest cells
    let half = quad / 2u;
    var count = 0u;
    for (var qv = 0u; qv < quads; qv++) {
        for (var qu = 0u; qu < quads; qu++) {
            var origin = lc * 4u;
            origin[a] += 4u;
            origin[u] += qu * quad;
            origin[v] += qv * quad;
            var du = vec3<u32>(0u);
            du[u] = half;
            var dv = vec3<u32>(0u);
            dv[v] = half;
            var config = 0u;
            for (var j = 0u; j < 3u; j++) {
                for (var i = 0u; i < 3u; i++) {
                    if fine_value(k, slot, fc, origin + i * du + j * dv) > level.iso {
                        config |= 1u << (i + 3u * j);
                    }
                }
            }
            let row = config * ROW;
            let tris = patterns[row];
            if write {
                for (var t = 0u; t < tris; t++) {
                    var e = vec3<u32>(0u);
                    for (var c = 0u; c < 3u; c++) {
                        // Face point p: a u-edge from (p % 2, p / 2) below 6, else a
                        // v-edge from ((p - 6) % 3, (p - 6) / 3), as `crack_gen::point_edge`.
                        let p = patterns[row + 1u + 3u * t + c];
                        var node = origin + (p % 2u) * du + (p / 2u) * dv;
                        var axis = u;
                        if p >= 6u {
                            node = origin + ((p - 6u) % 3u) * du + ((p - 6u) / 3u) * dv;
                            axis = v;
                        }
                        e[c] = fine_edge(edge_key(node, axis));
                    }
                    if flip {
                        e = e.xzy;
                    }
                    fills[first + count + t] = vec4<u32>(coarse + 1u, e);
                }
            }
            count += tris;
        }
    }
    return count;
}

@compute @workgroup_size(64)
fn count_fills(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let id = index_of(gid, nwg);
    if id >= level.count || coarse_side(id) != fine.coarse {
        return;
    }
    fill_counts[id] = walk_face(id, false, 0u);
}

@compute @workgroup_size(64)
fn emit_fills(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) nwg: vec3<u32>) {
    let id = index_of(gid, nwg);
    if id >= level.count || coarse_side(id) != fine.coarse {
        return;
    }
    walk_face(id, true, fill_counts[id]);
}
