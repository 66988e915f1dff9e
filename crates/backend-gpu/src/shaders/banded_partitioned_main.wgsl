// The partitioned banded solve alone (`banded.rs`, `Strategy::Partitioned`): its buffers and
// entry point around `partitioned_solve` of `banded_partitioned.wgsl`, which `banded.rs` puts
// after this file with `cholesky.wgsl`.

// The loops over a slice's elements and over the reduced system's levels take their bounds from
// here rather than from the constants, so that compilers keep them as loops instead of copying
// the whole elimination once per element and level.
struct Part {
    // Elements per invocation (EPT).
    per_thread: u32,
    // Invocations per rod (PT).
    threads: u32,
    pad0: u32,
    pad1: u32,
}

@group(0) @binding(0) var<uniform> band_part: Part;
// Block rows of every rod, padded and interleaved as `banded_partitioned.wgsl` says.
@group(0) @binding(1) var<storage, read> band_rows: array<REAL>;
// Right-hand sides (6 per element, same layout), overwritten with the solutions.
@group(0) @binding(3) var<storage, read_write> band_x: array<REAL>;

@compute @workgroup_size(PT)
fn partitioned(@builtin(local_invocation_index) t: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    partitioned_solve(wid.x, t);
}
