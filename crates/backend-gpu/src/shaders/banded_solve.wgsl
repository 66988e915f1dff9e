// The stiff scheme's banded system `(J K⁻¹ Jᵀ + α̃) Δλ = b` of many rods at once: a block LDLᵀ
// with 3×3 blocks, one rod per invocation (`banded.rs` says why and what it measured).
//
// A rod of n elements has `count = 2n − 1` block rows in the order (Γ0, Ω0, Γ1, Ω1, …, Γn−1).
// Block row k holds its symmetric diagonal block D (entries 00 01 02 11 12 22) and its blocks in
// block columns k + 1 (A1) and k + 2 (A2), row-major: 24 numbers (`ROW` below). The elimination
// is the CPU's `BlockTridiagonal` (backend-cpu `stiff/direct.rs`) step for step: a pivot is
// inverted in closed form when it is positive definite, else by a Cholesky factorisation whose
// non-positive pivots get an inverse of zero (a row no free degree of freedom can change keeps
// its multiplier); the factor keeps P⁻¹ (symmetric, 6), Y = P⁻¹ A1 and Z = P⁻¹ A2 (9 each).
//
// Every array is laid out rod-minor, `(k · ROW + entry) · rods + rod`, so that the invocations
// of a subgroup, which walk their rods' rows in lock step, read consecutive addresses.
//
// `REAL` is f64 (the production type: frame inverse inertias near 1e12 and compliances near
// 1e-11 make the matrix span more than f32 resolves) or f32 for measurement (`banded.rs`).

struct Shape {
    // Rods in the batch.
    rods: u32,
    // Block rows per rod (2n − 1).
    count: u32,
    // Elements per rod (n).
    elements: u32,
    pad: u32,
}

const ROW: u32 = 24u;

@group(0) @binding(0) var<uniform> shape: Shape;
// Block rows of every rod (`ROW` numbers each), read by `factor`.
@group(0) @binding(1) var<storage, read> rows: array<REAL>;
// The factor (`ROW` numbers per block row): written by `factor`, read by `solve`.
@group(0) @binding(2) var<storage, read_write> piv: array<REAL>;
// Right-hand sides (3 per block row), overwritten by `solve` with the solutions.
@group(0) @binding(3) var<storage, read_write> x: array<REAL>;

fn at(k: u32, e: u32, rod: u32) -> u32 {
    return (k * ROW + e) * shape.rods + rod;
}

fn xat(k: u32, c: u32, rod: u32) -> u32 {
    return (k * 3u + c) * shape.rods + rod;
}

// A row-major 3×3 block from `rows` or `piv` at entry `e0`, as a matrix with the same entries.
fn block_of_rows(k: u32, e0: u32, rod: u32) -> mat3x3<REAL> {
    var m: mat3x3<REAL>;
    for (var r = 0u; r < 3u; r++) {
        for (var c = 0u; c < 3u; c++) {
            m[c][r] = rows[at(k, e0 + 3u * r + c, rod)];
        }
    }
    return m;
}

fn block_of_piv(k: u32, e0: u32, rod: u32) -> mat3x3<REAL> {
    var m: mat3x3<REAL>;
    for (var r = 0u; r < 3u; r++) {
        for (var c = 0u; c < 3u; c++) {
            m[c][r] = piv[at(k, e0 + 3u * r + c, rod)];
        }
    }
    return m;
}

fn store_block(k: u32, e0: u32, rod: u32, m: mat3x3<REAL>) {
    for (var r = 0u; r < 3u; r++) {
        for (var c = 0u; c < 3u; c++) {
            piv[at(k, e0 + 3u * r + c, rod)] = m[c][r];
        }
    }
}

fn sym_of_piv(k: u32, rod: u32) -> mat3x3<REAL> {
    let a = piv[at(k, 0u, rod)];
    let b = piv[at(k, 1u, rod)];
    let c = piv[at(k, 2u, rod)];
    let d = piv[at(k, 3u, rod)];
    let e = piv[at(k, 4u, rod)];
    let f = piv[at(k, 5u, rod)];
    return mat3x3<REAL>(vec3<REAL>(a, b, c), vec3<REAL>(b, d, e), vec3<REAL>(c, e, f));
}

// The inverse of a symmetric positive semidefinite block by Cholesky, a non-positive pivot
// giving a zero row and column (`inverse_spd` of the CPU): A⁺ = L⁻ᵀ L⁻¹ (`cholesky.wgsl`).
fn inverse_psd(a: mat3x3<REAL>) -> mat3x3<REAL> {
    let m = chol_inv(a);
    return transpose(m) * m;
}

fn finite(v: REAL) -> bool {
    return v == v && abs(v) <= REAL(MAX_REAL);
}

@compute @workgroup_size(WG)
fn factor(@builtin(global_invocation_id) gid: vec3<u32>) {
    let rod = gid.x;
    if rod >= shape.rods {
        return;
    }
    let zero = mat3x3<REAL>(vec3<REAL>(), vec3<REAL>(), vec3<REAL>());
    // What the rows eliminated so far subtract from the next two diagonal blocks and the block
    // between them.
    var s11 = zero;
    var s12 = zero;
    var s22 = zero;
    for (var k = 0u; k < shape.count; k++) {
        let d00 = rows[at(k, 0u, rod)] - s11[0][0];
        let d01 = rows[at(k, 1u, rod)] - s11[1][0];
        let d02 = rows[at(k, 2u, rod)] - s11[2][0];
        let d11 = rows[at(k, 3u, rod)] - s11[1][1];
        let d12 = rows[at(k, 4u, rod)] - s11[2][1];
        let d22 = rows[at(k, 5u, rod)] - s11[2][2];
        let a1 = block_of_rows(k, 6u, rod) - s12;
        let a2 = block_of_rows(k, 15u, rod);
        let c00 = d11 * d22 - d12 * d12;
        let c01 = d12 * d02 - d01 * d22;
        let c02 = d01 * d12 - d11 * d02;
        let det = d00 * c00 + d01 * c01 + d02 * c02;
        var p_inv: mat3x3<REAL>;
        if det > REAL(0.0) && d00 > REAL(0.0) && c00 > REAL(0.0) && finite(det) {
            let c11 = d00 * d22 - d02 * d02;
            let c12 = d02 * d01 - d00 * d12;
            let c22 = d00 * d11 - d01 * d01;
            let adj = mat3x3<REAL>(vec3<REAL>(c00, c01, c02), vec3<REAL>(c01, c11, c12), vec3<REAL>(c02, c12, c22));
            p_inv = adj * (REAL(1.0) / det);
        } else {
            let d = mat3x3<REAL>(vec3<REAL>(d00, d01, d02), vec3<REAL>(d01, d11, d12), vec3<REAL>(d02, d12, d22));
            p_inv = inverse_psd(d);
        }
        let y = p_inv * a1;
        let z = p_inv * a2;
        s11 = transpose(a1) * y + s22;
        s12 = transpose(a1) * z;
        s22 = transpose(a2) * z;
        piv[at(k, 0u, rod)] = p_inv[0][0];
        piv[at(k, 1u, rod)] = p_inv[1][0];
        piv[at(k, 2u, rod)] = p_inv[2][0];
        piv[at(k, 3u, rod)] = p_inv[1][1];
        piv[at(k, 4u, rod)] = p_inv[2][1];
        piv[at(k, 5u, rod)] = p_inv[2][2];
        store_block(k, 6u, rod, y);
        store_block(k, 15u, rod, z);
    }
}

@compute @workgroup_size(WG)
fn solve(@builtin(global_invocation_id) gid: vec3<u32>) {
    let rod = gid.x;
    if rod >= shape.rods {
        return;
    }
    // Forward: z_k = b_k − Y_{k−1}ᵀ z_{k−1} − Z_{k−2}ᵀ z_{k−2}, then w_k = P_k⁻¹ z_k.
    var z1 = vec3<REAL>();
    var z2 = vec3<REAL>();
    for (var k = 0u; k < shape.count; k++) {
        var b = vec3<REAL>(x[xat(k, 0u, rod)], x[xat(k, 1u, rod)], x[xat(k, 2u, rod)]);
        if k >= 2u {
            b -= transpose(block_of_piv(k - 2u, 15u, rod)) * z2;
        }
        if k >= 1u {
            b -= transpose(block_of_piv(k - 1u, 6u, rod)) * z1;
        }
        z2 = z1;
        z1 = b;
        let w = sym_of_piv(k, rod) * b;
        x[xat(k, 0u, rod)] = w.x;
        x[xat(k, 1u, rod)] = w.y;
        x[xat(k, 2u, rod)] = w.z;
    }
    // Backward: x_k = w_k − Y_k x_{k+1} − Z_k x_{k+2}.
    var x1 = vec3<REAL>();
    var x2 = vec3<REAL>();
    for (var i = 0u; i < shape.count; i++) {
        let k = shape.count - 1u - i;
        let w = vec3<REAL>(x[xat(k, 0u, rod)], x[xat(k, 1u, rod)], x[xat(k, 2u, rod)]);
        let v = w - block_of_piv(k, 15u, rod) * x2 - block_of_piv(k, 6u, rod) * x1;
        x2 = x1;
        x1 = v;
        x[xat(k, 0u, rod)] = v.x;
        x[xat(k, 1u, rod)] = v.y;
        x[xat(k, 2u, rod)] = v.z;
    }
}

// ---------------------------------------------------------------------------------------------
// One rod per workgroup: block cyclic reduction.
//
// The same system seen as block tridiagonal with 6×6 blocks, one per element j = (Γj, Ωj):
// B_j = [[D_Γj, (Γj,Ωj)], [(Γj,Ωj)ᵀ, D_Ωj]] on the diagonal and C_j = [[(Γj,Γj+1), 0],
// [(Ωj,Γj+1), (Ωj,Ωj+1)]] above it (A_j = C_{j−1}ᵀ below); the last element's missing Ω row is an
// identity row with a zero right-hand side. At level s = 1, 2, 4, … the rows e ≡ s (mod 2s)
// are eliminated from their neighbours i = e ± s, all at once: each e inverts B_e, then each
// i ≡ 0 (mod 2s) takes α = −A_i B_{i−s}⁻¹, γ = −C_i B_{i+s}⁻¹ and becomes
// B_i + α C_{i−s} + γ A_{i+s}, coupled to i ∓ 2s by α A_{i−s} and γ C_{i+s}. Row 0 is left and
// solved; the eliminated rows are then solved from the top level down,
// x_e = B_e⁻¹ (f_e − A_e x_{e−s} − C_e x_{e+s}). `log₂ n` levels of independent work each,
// against the `2n − 1` dependent eliminations of the chain above.
//
// Per element the factor keeps (in `cr`, rod-major, `CR_STRIDE` numbers): B, A, C (as last
// used), B⁻¹, the α of the row above it and the γ of the row below it (each row is eliminated
// once, next to exactly one updated row on either side), the right-hand side and the solution.

const CR_B: u32 = 0u;
const CR_A: u32 = 36u;
const CR_C: u32 = 72u;
const CR_BINV: u32 = 108u;
const CR_AL: u32 = 144u;
const CR_GA: u32 = 180u;
const CR_F: u32 = 216u;
const CR_X: u32 = 222u;
const CR_STRIDE: u32 = 228u;

@group(0) @binding(4) var<storage, read_write> cr: array<REAL>;

fn cr_at(rod: u32, j: u32, field: u32) -> u32 {
    return (rod * shape.elements + j) * CR_STRIDE + field;
}

// dst += a b.
fn cr_mul_add(dst: u32, a: u32, b: u32) {
    for (var r = 0u; r < 6u; r++) {
        var row: array<REAL, 6>;
        for (var c = 0u; c < 6u; c++) {
            row[c] = cr[dst + 6u * r + c];
        }
        for (var k = 0u; k < 6u; k++) {
            let ark = cr[a + 6u * r + k];
            for (var c = 0u; c < 6u; c++) {
                row[c] += ark * cr[b + 6u * k + c];
            }
        }
        for (var c = 0u; c < 6u; c++) {
            cr[dst + 6u * r + c] = row[c];
        }
    }
}

// dst = a b (6×6, row-major; dst aliases neither).
fn cr_mul(dst: u32, a: u32, b: u32) {
    for (var i = 0u; i < 36u; i++) {
        cr[dst + i] = REAL(0.0);
    }
    cr_mul_add(dst, a, b);
}

// dst = −a b.
fn cr_mul_neg(dst: u32, a: u32, b: u32) {
    cr_mul(dst, a, b);
    for (var i = 0u; i < 36u; i++) {
        cr[dst + i] = -cr[dst + i];
    }
}

// y += s · a x for 6-vectors at `y`, `x`.
fn cr_mat_vec(y: u32, a: u32, x: u32, s: REAL) {
    for (var r = 0u; r < 6u; r++) {
        var acc = REAL(0.0);
        for (var k = 0u; k < 6u; k++) {
            acc += cr[a + 6u * r + k] * cr[x + k];
        }
        cr[y + r] += s * acc;
    }
}

// dst = B⁺ of the symmetric positive semidefinite 6×6 block at `b`: Cholesky with a zero
// inverse for a non-positive pivot (as `inverse_psd`), then L⁻ᵀ L⁻¹.
fn cr_inverse(dst: u32, b: u32) {
    var l: array<REAL, 36>;
    for (var j = 0u; j < 6u; j++) {
        var d = cr[b + 7u * j];
        for (var k = 0u; k < j; k++) {
            d -= l[6u * j + k] * l[6u * j + k];
        }
        var inv = REAL(0.0);
        if d > REAL(0.0) {
            inv = REAL(1.0) / sqrt(d);
        }
        l[7u * j] = inv;
        for (var i = j + 1u; i < 6u; i++) {
            var s = cr[b + 6u * i + j];
            for (var k = 0u; k < j; k++) {
                s -= l[6u * i + k] * l[6u * j + k];
            }
            l[6u * i + j] = s * inv;
        }
    }
    // m = L⁻¹ (lower), column by column.
    var m: array<REAL, 36>;
    for (var c = 0u; c < 6u; c++) {
        for (var i = c; i < 6u; i++) {
            var s = select(REAL(0.0), REAL(1.0), i == c);
            for (var k = c; k < i; k++) {
                s -= l[6u * i + k] * m[6u * k + c];
            }
            m[6u * i + c] = s * l[7u * i];
        }
    }
    for (var r = 0u; r < 6u; r++) {
        for (var c = r; c < 6u; c++) {
            var s = REAL(0.0);
            for (var k = c; k < 6u; k++) {
                s += m[6u * k + r] * m[6u * k + c];
            }
            cr[dst + 6u * r + c] = s;
            cr[dst + 6u * c + r] = s;
        }
    }
}

// Entry (r, c) of the 3×3 block at entry e0 of block row k (row-major), from `rows`.
fn row_entry(k: u32, e0: u32, r: u32, c: u32, rod: u32) -> REAL {
    return rows[at(k, e0 + 3u * r + c, rod)];
}

fn row_diag(k: u32, r: u32, c: u32, rod: u32) -> REAL {
    let lo = min(r, c);
    let hi = max(r, c);
    // 00 01 02 11 12 22
    let idx = select(select(5u, 3u + hi - 1u, lo == 1u), hi, lo == 0u);
    return rows[at(k, idx, rod)];
}

@compute @workgroup_size(CR_WG)
fn factor_cr(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let rod = wid.x;
    let n = shape.elements;
    // The 6×6 blocks from the 3×3 block rows.
    for (var j = lid; j < n; j += CR_WG) {
        let kg = 2u * j;
        let ko = 2u * j + 1u;
        let has_o = ko < shape.count;
        let b = cr_at(rod, j, CR_B);
        let c = cr_at(rod, j, CR_C);
        for (var r = 0u; r < 3u; r++) {
            for (var q = 0u; q < 3u; q++) {
                cr[b + 6u * r + q] = row_diag(kg, r, q, rod);
                var go = REAL(0.0);
                var oo = select(REAL(0.0), REAL(1.0), r == q);
                let gn = row_entry(kg, 15u, r, q, rod);
                var on = REAL(0.0);
                var oon = REAL(0.0);
                if has_o {
                    go = row_entry(kg, 6u, r, q, rod);
                    oo = row_diag(ko, r, q, rod);
                    on = row_entry(ko, 6u, r, q, rod);
                    oon = row_entry(ko, 15u, r, q, rod);
                }
                cr[b + 6u * r + q + 3u] = go;
                cr[b + 6u * (q + 3u) + r] = go;
                cr[b + 6u * (r + 3u) + q + 3u] = oo;
                // C_j: (Γj, Γj+1), 0; (Ωj, Γj+1), (Ωj, Ωj+1).
                cr[c + 6u * r + q] = gn;
                cr[c + 6u * r + q + 3u] = REAL(0.0);
                cr[c + 6u * (r + 3u) + q] = on;
                cr[c + 6u * (r + 3u) + q + 3u] = oon;
            }
        }
    }
    storageBarrier();
    workgroupBarrier();
    for (var j = lid; j < n; j += CR_WG) {
        // A_j = C_{j−1}ᵀ.
        let a = cr_at(rod, j, CR_A);
        for (var r = 0u; r < 6u; r++) {
            for (var q = 0u; q < 6u; q++) {
                var v = REAL(0.0);
                if j > 0u {
                    v = cr[cr_at(rod, j - 1u, CR_C) + 6u * q + r];
                }
                cr[a + 6u * r + q] = v;
            }
        }
    }
    storageBarrier();
    workgroupBarrier();
    for (var s = 1u; s < n; s *= 2u) {
        for (var e = lid * 2u * s + s; e < n; e += CR_WG * 2u * s) {
            cr_inverse(cr_at(rod, e, CR_BINV), cr_at(rod, e, CR_B));
        }
        storageBarrier();
        workgroupBarrier();
        for (var i = lid * 2u * s; i < n; i += CR_WG * 2u * s) {
            let bi = cr_at(rod, i, CR_B);
            let has_l = i >= s;
            let has_r = i + s < n;
            if has_l {
                // α = −A_i B_{i−s}⁻¹, kept with row i − s.
                let al = cr_at(rod, i - s, CR_AL);
                cr_mul_neg(al, cr_at(rod, i, CR_A), cr_at(rod, i - s, CR_BINV));
                cr_mul_add(bi, al, cr_at(rod, i - s, CR_C));
            }
            if has_r {
                let ga = cr_at(rod, i + s, CR_GA);
                cr_mul_neg(ga, cr_at(rod, i, CR_C), cr_at(rod, i + s, CR_BINV));
                cr_mul_add(bi, ga, cr_at(rod, i + s, CR_A));
            }
            if has_l {
                cr_mul(cr_at(rod, i, CR_A), cr_at(rod, i - s, CR_AL), cr_at(rod, i - s, CR_A));
            }
            let ci = cr_at(rod, i, CR_C);
            if has_r {
                cr_mul(ci, cr_at(rod, i + s, CR_GA), cr_at(rod, i + s, CR_C));
            } else {
                for (var k = 0u; k < 36u; k++) {
                    cr[ci + k] = REAL(0.0);
                }
            }
        }
        storageBarrier();
        workgroupBarrier();
    }
    if lid == 0u {
        cr_inverse(cr_at(rod, 0u, CR_BINV), cr_at(rod, 0u, CR_B));
    }
}

@compute @workgroup_size(CR_WG)
fn solve_cr(@builtin(local_invocation_index) lid: u32, @builtin(workgroup_id) wid: vec3<u32>) {
    let rod = wid.x;
    let n = shape.elements;
    for (var j = lid; j < n; j += CR_WG) {
        let f = cr_at(rod, j, CR_F);
        for (var c = 0u; c < 3u; c++) {
            cr[f + c] = x[xat(2u * j, c, rod)];
            var o = REAL(0.0);
            if 2u * j + 1u < shape.count {
                o = x[xat(2u * j + 1u, c, rod)];
            }
            cr[f + 3u + c] = o;
        }
    }
    storageBarrier();
    workgroupBarrier();
    // Forward: the right-hand sides follow the eliminations.
    var top = 1u;
    for (var s = 1u; s < n; s *= 2u) {
        for (var i = lid * 2u * s; i < n; i += CR_WG * 2u * s) {
            let fi = cr_at(rod, i, CR_F);
            if i >= s {
                cr_mat_vec(fi, cr_at(rod, i - s, CR_AL), cr_at(rod, i - s, CR_F), REAL(1.0));
            }
            if i + s < n {
                cr_mat_vec(fi, cr_at(rod, i + s, CR_GA), cr_at(rod, i + s, CR_F), REAL(1.0));
            }
        }
        storageBarrier();
        workgroupBarrier();
        top = s;
    }
    if lid == 0u {
        let x0 = cr_at(rod, 0u, CR_X);
        for (var k = 0u; k < 6u; k++) {
            cr[x0 + k] = REAL(0.0);
        }
        cr_mat_vec(x0, cr_at(rod, 0u, CR_BINV), cr_at(rod, 0u, CR_F), REAL(1.0));
    }
    storageBarrier();
    workgroupBarrier();
    // Backward, from the top level down.
    for (var s = top; s >= 1u; s /= 2u) {
        if s >= n {
            continue;
        }
        for (var e = lid * 2u * s + s; e < n; e += CR_WG * 2u * s) {
            let f = cr_at(rod, e, CR_F);
            cr_mat_vec(f, cr_at(rod, e, CR_A), cr_at(rod, e - s, CR_X), REAL(-1.0));
            if e + s < n {
                cr_mat_vec(f, cr_at(rod, e, CR_C), cr_at(rod, e + s, CR_X), REAL(-1.0));
            }
            let xe = cr_at(rod, e, CR_X);
            for (var k = 0u; k < 6u; k++) {
                cr[xe + k] = REAL(0.0);
            }
            cr_mat_vec(xe, cr_at(rod, e, CR_BINV), f, REAL(1.0));
        }
        storageBarrier();
        workgroupBarrier();
    }
    for (var j = lid; j < n; j += CR_WG) {
        let xj = cr_at(rod, j, CR_X);
        for (var c = 0u; c < 3u; c++) {
            x[xat(2u * j, c, rod)] = cr[xj + c];
            if 2u * j + 1u < shape.count {
                x[xat(2u * j + 1u, c, rod)] = cr[xj + 3u + c];
            }
        }
    }
}
