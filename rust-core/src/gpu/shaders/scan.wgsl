// Exclusive prefix sum of `data[0..count]` in blocks of 64: each block scans itself and
// writes its total to `sums`; the host scans `sums` the same way and `add_sums` adds each
// block's prefix back. Sums are in a fixed order, so the result is deterministic.

struct Scan {
    count: u32,
    pad0: u32,
    pad1: u32,
    pad2: u32,
}

@group(0) @binding(0) var<storage, read_write> data: array<u32>;
@group(0) @binding(1) var<storage, read_write> sums: array<u32>;
@group(0) @binding(2) var<uniform> scan: Scan;

var<workgroup> tile: array<u32, 64>;

@compute @workgroup_size(64)
fn scan_blocks(
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let block = wid.x + wid.y * nwg.x;
    let i = block * 64u + lid.x;
    var v = 0u;
    if i < scan.count {
        v = data[i];
    }
    tile[lid.x] = v;
    workgroupBarrier();
    for (var off = 1u; off < 64u; off *= 2u) {
        var t = 0u;
        if lid.x >= off {
            t = tile[lid.x - off];
        }
        workgroupBarrier();
        tile[lid.x] += t;
        workgroupBarrier();
    }
    if i < scan.count {
        data[i] = tile[lid.x] - v;
    }
    if lid.x == 63u && block * 64u < scan.count {
        sums[block] = tile[63];
    }
}

@compute @workgroup_size(64)
fn add_sums(
    @builtin(local_invocation_id) lid: vec3<u32>,
    @builtin(workgroup_id) wid: vec3<u32>,
    @builtin(num_workgroups) nwg: vec3<u32>,
) {
    let block = wid.x + wid.y * nwg.x;
    let i = block * 64u + lid.x;
    if i < scan.count {
        data[i] += sums[block];
    }
}
