// The stiff scheme's banded system `(J K⁻¹ Jᵀ + α̃) Δλ = b` of many rods at once, one rod per
// workgroup, partitioned: every invocation eliminates its own slice of the rod in private
// memory, the invocations' boundary rows are solved together by cyclic reduction through
// workgroup memory, and every invocation back-substitutes its slice (`banded.rs` says why).
//
// The system is seen as block tridiagonal with 6×6 blocks, one per element j = (Γj, Ωj):
// B_j = [[D_Γj, (Γj,Ωj)], [(Γj,Ωj)ᵀ, D_Ωj]] on the diagonal, C_j = [[(Γj,Γj+1), 0],
// [(Ωj,Γj+1), (Ωj,Ωj+1)]] above it and C_jᵀ below it. The host pads the rod to PT · EPT elements
// with identity rows (the last element's missing Ω row and whole elements past the rod), so
// that every invocation owns exactly EPT elements and the kernel never asks where the rod ends:
// the padding's couplings are zero and its right-hand sides too, so it solves to zero.
//
// Invocation t owns elements tEPT … tEPT + EPT − 1. Its first element is its *separator* a; the
// others are its interior. Eliminating the interior in order (a chain of EPT − 1 steps in
// private memory) leaves, for interior element j, the equation D_j x_j + C_j x_{j+1} + G_j x_a
// = g_j, with D_1 = B_1, G_1 = C_aᵀ, g_1 = f_1 and, with P = D_j⁺,
//   D_{j+1} = B_{j+1} − C_jᵀ P C_j,  G_{j+1} = −C_jᵀ P G_j,  g_{j+1} = f_{j+1} − C_jᵀ P g_j,
// while the separator takes B_a −= G_jᵀ P G_j, f_a −= G_jᵀ P g_j (the spike of the partition).
// What the last step leaves for "element EPT" is the next invocation's separator: its diagonal
// and right-hand side get −C_jᵀ P C_j and −C_jᵀ P g_j, and G_EPTᵀ is the coupling between the
// two separators. That is the block LDLᵀ of a symmetric permutation of the system (interiors
// first, separators last), backward stable as the chain's is for positive definite systems
// (which badly conditioned rods an f32 solve loses does depend on the order: `tests/banded.rs`).
//
// The reduced system, one 6×6 row per invocation, is block tridiagonal again and is solved by
// block cyclic reduction (`log₂ PT` levels): at level s each row e ≡ s (mod 2s) is eliminated
// by its own invocation, which computes with P = B_e⁺ everything its two neighbours need
// (C_e and A_e, its couplings to e ± s, are the transposes of theirs to it):
//   for e − s: B −= A_eᵀ P A_e, f −= A_eᵀ P f_e;  for e + s: B −= C_eᵀ P C_e, f −= C_eᵀ P f_e;
//   the new coupling between e − s and e + s: −A_eᵀ P C_e,
// and keeps P A_e, P C_e and P f_e to find x_e = P f_e − P A_e x_{e−s} − P C_e x_{e+s} on the
// way back. These go through one workgroup array of 27 · PT numbers in two rounds per level
// (couplings and right-hand sides, then the symmetric diagonal updates), small enough that 64
// invocations fit the default 16 KiB in f64. The solutions of the separators then go through
// the same array, and every invocation back-substitutes its interior,
// x_j = P g_j − P C_j x_{j+1} − P G_j x_a, and writes its elements' solutions.
//
// No pivot is inverted explicitly: each 6×6 pivot D = L Lᵀ is factorised by Cholesky (by 3×3
// blocks), its non-positive pivots giving a zero row and column of L⁻¹ (as the cyclic
// reduction's `cr_inverse` in `banded_solve.wgsl`): a row no free degree of freedom reaches
// keeps a zero multiplier. The blocks it multiplies are scaled by L⁻¹ once (Ŷ = L⁻¹ C, …),
// and every update −Xᵀ P Y is the product −X̂ᵀ Ŷ of two of them: P = L⁻ᵀ L⁻¹ is never formed,
// the symmetric updates take half their products, and the zero block of C_j (Γj has no
// coupling to Ωj+1) is skipped: 41 3×3 products per interior element instead of 48, and the
// chain from one pivot to the next no longer waits for P to be formed. On an H100 this made the
// f64 solve 1.2× (one rod) to 1.5× (4096 rods) faster (`docs/benchmarks/stiff-gpu.md`, "Second
// round"); the results differ from the explicit inverse's by rounding only.
//
// Rows and right-hand sides are laid out so that a workgroup's loads coalesce: number q of
// element j of invocation t's slice of rod r sits at `((r · EPT + j) · Q + q) · PT + t` (Q = 48:
// block rows 2j and 2j + 1, 24 numbers each, for the matrix; Q = 6 for the vectors).
//
// A 6×6 block is kept as its four 3×3 blocks (`M6`), so that every product is a handful of
// mat3x3 products a compiler keeps in registers, with no loops over a block's entries and no
// arrays of numbers passed around (lavapipe takes half a minute over a kernel written so).
//
// Filled in by `banded.rs`: REAL (f64 or f32); prepended: the constants PT (invocations per rod,
// a power of two), EPT (elements per invocation) and XCH (numbers in `xch`: 27 · PT, at least 36).
// The file that includes it declares the buffers `band_rows` (the block rows) and `band_x` (the
// right-hand sides, overwritten with the solutions) and a uniform `band_part` with the fields
// `per_thread` (EPT) and `threads` (PT): `banded_partitioned_main.wgsl` for the solve alone,
// `stiff_step.wgsl` for the stiff step that assembles the rows itself. The loops take their
// bounds from it rather than from the constants: bounded by EPT instead, so that a compiler
// could unroll the slice's loops and index `ys`, `zs`, `ws` by constants, the solve was no
// faster on an H100 (`docs/benchmarks/stiff-gpu.md`), so they stay loops.

// [[a, b], [c, d]]: each field the 3×3 block itself (entry (r, c) of `a` is a[c][r]).
struct M6 {
    a: mat3x3<REAL>,
    b: mat3x3<REAL>,
    c: mat3x3<REAL>,
    d: mat3x3<REAL>,
}

// (u, v): the Γ and Ω parts.
struct V6 {
    u: vec3<REAL>,
    v: vec3<REAL>,
}

// Numbers per element in `band_rows`: block rows 2j and 2j + 1.
const PQ: u32 = 48u;
// Numbers per invocation in `xch`.
const XQ: u32 = 27u;

// The reduced system's exchange, then the separators' solutions.
var<workgroup> xch: array<REAL, XCH>;

fn pr(rod: u32, j: u32, q: u32, t: u32) -> REAL {
    return band_rows[((rod * EPT + j) * PQ + q) * PT + t];
}

fn px(rod: u32, j: u32, c: u32, t: u32) -> u32 {
    return ((rod * EPT + j) * 6u + c) * PT + t;
}

// The row-major 3×3 block at number q0 of element j.
fn row_block(rod: u32, j: u32, q0: u32, t: u32) -> mat3x3<REAL> {
    return transpose(mat3x3<REAL>(
        vec3<REAL>(pr(rod, j, q0, t), pr(rod, j, q0 + 1u, t), pr(rod, j, q0 + 2u, t)),
        vec3<REAL>(pr(rod, j, q0 + 3u, t), pr(rod, j, q0 + 4u, t), pr(rod, j, q0 + 5u, t)),
        vec3<REAL>(pr(rod, j, q0 + 6u, t), pr(rod, j, q0 + 7u, t), pr(rod, j, q0 + 8u, t)),
    ));
}

// The symmetric 3×3 block stored as 00 01 02 11 12 22 at number q0 of element j.
fn row_sym(rod: u32, j: u32, q0: u32, t: u32) -> mat3x3<REAL> {
    let a = pr(rod, j, q0, t);
    let b = pr(rod, j, q0 + 1u, t);
    let c = pr(rod, j, q0 + 2u, t);
    let d = pr(rod, j, q0 + 3u, t);
    let e = pr(rod, j, q0 + 4u, t);
    let f = pr(rod, j, q0 + 5u, t);
    return mat3x3<REAL>(vec3<REAL>(a, b, c), vec3<REAL>(b, d, e), vec3<REAL>(c, e, f));
}

// B_j of invocation t's element j.
fn load_b(rod: u32, j: u32, t: u32) -> M6 {
    let go = row_block(rod, j, 6u, t);
    return M6(row_sym(rod, j, 0u, t), go, transpose(go), row_sym(rod, j, 24u, t));
}

// C_j: the coupling of invocation t's element j to the element after it.
fn load_c(rod: u32, j: u32, t: u32) -> M6 {
    let zero = mat3x3<REAL>(vec3<REAL>(), vec3<REAL>(), vec3<REAL>());
    return M6(row_block(rod, j, 15u, t), zero, row_block(rod, j, 30u, t), row_block(rod, j, 39u, t));
}

fn load_f(rod: u32, j: u32, t: u32) -> V6 {
    return V6(
        vec3<REAL>(band_x[px(rod, j, 0u, t)], band_x[px(rod, j, 1u, t)], band_x[px(rod, j, 2u, t)]),
        vec3<REAL>(band_x[px(rod, j, 3u, t)], band_x[px(rod, j, 4u, t)], band_x[px(rod, j, 5u, t)]),
    );
}

fn store_x(rod: u32, j: u32, t: u32, v: V6) {
    band_x[px(rod, j, 0u, t)] = v.u.x;
    band_x[px(rod, j, 1u, t)] = v.u.y;
    band_x[px(rod, j, 2u, t)] = v.u.z;
    band_x[px(rod, j, 3u, t)] = v.v.x;
    band_x[px(rod, j, 4u, t)] = v.v.y;
    band_x[px(rod, j, 5u, t)] = v.v.z;
}

// L⁻¹ of the Cholesky factor L of a symmetric positive semidefinite 6×6 block, as its three
// 3×3 blocks: [[m1, 0], [k, m2]] with m1 and m2 lower triangular.
struct L6 {
    m1: mat3x3<REAL>,
    k: mat3x3<REAL>,
    m2: mat3x3<REAL>,
}

fn zero3() -> mat3x3<REAL> {
    return mat3x3<REAL>(vec3<REAL>(), vec3<REAL>(), vec3<REAL>());
}

fn transpose6(p: M6) -> M6 {
    return M6(transpose(p.a), transpose(p.c), transpose(p.b), transpose(p.d));
}

fn add_v(p: V6, q: V6) -> V6 {
    return V6(p.u + q.u, p.v + q.v);
}

// p + q of two symmetric blocks: the sum's c is taken as the transpose of its b (27 numbers
// computed rather than 36).
fn add_sym(p: M6, q: M6) -> M6 {
    let b = p.b + q.b;
    return M6(p.a + q.a, b, transpose(b), p.d + q.d);
}

// B = L Lᵀ taken by 3×3 blocks, L = [[L₁, 0], [Wᵀ, L₂]] with W = L₁⁻¹ B₁₂ and L₂ the factor
// of the Schur complement B₂₂ − Wᵀ W (a Gram product, positive semidefinite as computed), each
// non-positive pivot giving a zero row and column of L⁻¹ (the 6×6 Cholesky of the cyclic
// reduction's `cr_inverse`, blockwise); L⁻¹ = [[M₁, 0], [K, M₂]], K = −M₂ Wᵀ M₁. Only the
// lower triangles of B's diagonal blocks are read.
fn chol6(p: M6) -> L6 {
    let m1 = chol_inv(p.a);
    let w = m1 * p.b;
    let m2 = chol_inv(p.d - transpose(w) * w);
    return L6(m1, (m2 * transpose(w) * m1) * REAL(-1.0), m2);
}

// L⁻¹ q.
fn lmul(l: L6, q: M6) -> M6 {
    return M6(l.m1 * q.a, l.m1 * q.b, l.k * q.a + l.m2 * q.c, l.k * q.b + l.m2 * q.d);
}

// L⁻¹ q for a q whose b block is zero (a coupling C_j), and so is the product's.
fn lmul_c(l: L6, q: M6) -> M6 {
    return M6(l.m1 * q.a, zero3(), l.k * q.a + l.m2 * q.c, l.m2 * q.d);
}

// L⁻¹ v.
fn lmul_v(l: L6, v: V6) -> V6 {
    return V6(l.m1 * v.u, l.k * v.u + l.m2 * v.v);
}

// L⁻ᵀ q = [[M₁ᵀ, Kᵀ], [0, M₂ᵀ]] q.
fn ltmul(l: L6, q: M6) -> M6 {
    let t1 = transpose(l.m1);
    let tk = transpose(l.k);
    let t2 = transpose(l.m2);
    return M6(t1 * q.a + tk * q.c, t1 * q.b + tk * q.d, t2 * q.c, t2 * q.d);
}

// L⁻ᵀ q for a q whose b block is zero.
fn ltmul_c(l: L6, q: M6) -> M6 {
    let tk = transpose(l.k);
    let t2 = transpose(l.m2);
    return M6(transpose(l.m1) * q.a + tk * q.c, tk * q.d, t2 * q.c, t2 * q.d);
}

// L⁻ᵀ v (`v * m` is mᵀ v in WGSL).
fn ltmul_v(l: L6, v: V6) -> V6 {
    return V6(v.u * l.m1 + v.v * l.k, v.v * l.m2);
}

// −pᵀ q.
fn neg_tmul(p: M6, q: M6) -> M6 {
    // (WGSL has no negation of matrices.)
    let ta = transpose(p.a) * REAL(-1.0);
    let tb = transpose(p.b) * REAL(-1.0);
    let tc = transpose(p.c) * REAL(-1.0);
    let td = transpose(p.d) * REAL(-1.0);
    return M6(ta * q.a + tc * q.c, ta * q.b + tc * q.d, tb * q.a + td * q.c, tb * q.b + td * q.d);
}

// −pᵀ q for a p whose b block is zero.
fn neg_tmul_c(p: M6, q: M6) -> M6 {
    let ta = transpose(p.a) * REAL(-1.0);
    let tc = transpose(p.c) * REAL(-1.0);
    let td = transpose(p.d) * REAL(-1.0);
    return M6(ta * q.a + tc * q.c, ta * q.b + tc * q.d, td * q.c, td * q.d);
}

// −pᵀ p, symmetric: six 3×3 products instead of eight.
fn neg_gram(p: M6) -> M6 {
    let ta = transpose(p.a) * REAL(-1.0);
    let tc = transpose(p.c) * REAL(-1.0);
    let b = ta * p.b + tc * p.d;
    return M6(ta * p.a + tc * p.c, b, transpose(b), (transpose(p.b) * REAL(-1.0)) * p.b + (transpose(p.d) * REAL(-1.0)) * p.d);
}

// −pᵀ p for a p whose b block is zero: four products.
fn neg_gram_c(p: M6) -> M6 {
    let tc = transpose(p.c) * REAL(-1.0);
    let b = tc * p.d;
    return M6((transpose(p.a) * REAL(-1.0)) * p.a + tc * p.c, b, transpose(b), (transpose(p.d) * REAL(-1.0)) * p.d);
}

// −p v.
fn neg_mul_v(p: M6, v: V6) -> V6 {
    return V6(-(p.a * v.u + p.b * v.v), -(p.c * v.u + p.d * v.v));
}

// −pᵀ v.
fn neg_tmul_v(p: M6, v: V6) -> V6 {
    return V6(-(v.u * p.a + v.v * p.c), -(v.u * p.b + v.v * p.d));
}

// −pᵀ v for a p whose b block is zero.
fn neg_tmul_v_c(p: M6, v: V6) -> V6 {
    return V6(-(v.u * p.a + v.v * p.c), -(v.v * p.d));
}

// The exchange array as blocks: 3×3 (9 numbers, row-major), 6×6 (36), symmetric 6×6 (a's and
// d's upper triangles and b: 21) and 6-vectors.
fn put3(at: u32, m: mat3x3<REAL>) {
    xch[at] = m[0][0];
    xch[at + 1u] = m[1][0];
    xch[at + 2u] = m[2][0];
    xch[at + 3u] = m[0][1];
    xch[at + 4u] = m[1][1];
    xch[at + 5u] = m[2][1];
    xch[at + 6u] = m[0][2];
    xch[at + 7u] = m[1][2];
    xch[at + 8u] = m[2][2];
}

fn get3(at: u32) -> mat3x3<REAL> {
    return transpose(mat3x3<REAL>(
        vec3<REAL>(xch[at], xch[at + 1u], xch[at + 2u]),
        vec3<REAL>(xch[at + 3u], xch[at + 4u], xch[at + 5u]),
        vec3<REAL>(xch[at + 6u], xch[at + 7u], xch[at + 8u]),
    ));
}

fn put_sym3(at: u32, m: mat3x3<REAL>) {
    xch[at] = m[0][0];
    xch[at + 1u] = m[1][0];
    xch[at + 2u] = m[2][0];
    xch[at + 3u] = m[1][1];
    xch[at + 4u] = m[2][1];
    xch[at + 5u] = m[2][2];
}

fn get_sym3(at: u32) -> mat3x3<REAL> {
    let a = xch[at];
    let b = xch[at + 1u];
    let c = xch[at + 2u];
    let d = xch[at + 3u];
    let e = xch[at + 4u];
    let f = xch[at + 5u];
    return mat3x3<REAL>(vec3<REAL>(a, b, c), vec3<REAL>(b, d, e), vec3<REAL>(c, e, f));
}

fn put_m(at: u32, m: M6) {
    put3(at, m.a);
    put3(at + 9u, m.b);
    put3(at + 18u, m.c);
    put3(at + 27u, m.d);
}

fn get_m(at: u32) -> M6 {
    return M6(get3(at), get3(at + 9u), get3(at + 18u), get3(at + 27u));
}

fn put_sym(at: u32, m: M6) {
    put_sym3(at, m.a);
    put3(at + 6u, m.b);
    put_sym3(at + 15u, m.d);
}

fn get_sym(at: u32) -> M6 {
    let b = get3(at + 6u);
    return M6(get_sym3(at), b, transpose(b), get_sym3(at + 15u));
}

fn put_v(at: u32, v: V6) {
    xch[at] = v.u.x;
    xch[at + 1u] = v.u.y;
    xch[at + 2u] = v.u.z;
    xch[at + 3u] = v.v.x;
    xch[at + 4u] = v.v.y;
    xch[at + 5u] = v.v.z;
}

fn get_v(at: u32) -> V6 {
    return V6(vec3<REAL>(xch[at], xch[at + 1u], xch[at + 2u]), vec3<REAL>(xch[at + 3u], xch[at + 4u], xch[at + 5u]));
}

// Factorises and solves rod `rod`'s system in `band_rows`, `band_x` (invocation `t` of its
// workgroup; every invocation calls it, in uniform control flow).
fn partitioned_solve(rod: u32, t: u32) {
    // The separator, then the interior in order. `dn`, `gn`, `fnext` are what the elements
    // eliminated so far leave for the next one (`gn`: its coupling to the separator).
    var b = load_b(rod, 0u, t);
    var f = load_f(rod, 0u, t);
    var gn = transpose6(load_c(rod, 0u, t));
    let zero = zero3();
    var dn = M6(zero, zero, zero, zero);
    var fnext = V6(vec3<REAL>(), vec3<REAL>());
    // P C_j, P G_j and P g_j of every interior element, for the back-substitution.
    var ys: array<M6, EPT>;
    var zs: array<M6, EPT>;
    var ws: array<V6, EPT>;
    for (var j = 1u; j < band_part.per_thread; j++) {
        // With P = L⁻ᵀ L⁻¹: Ŷ = L⁻¹ C_j, Ẑ = L⁻¹ G_j, ŵ = L⁻¹ g_j, and every update is a
        // product of two of them (−C_jᵀ P C_j = −Ŷᵀ Ŷ, …), symmetric ones by half.
        let l = chol6(add_sym(load_b(rod, j, t), dn));
        let yh = lmul_c(l, load_c(rod, j, t));
        let zh = lmul(l, gn);
        let wh = lmul_v(l, add_v(load_f(rod, j, t), fnext));
        b = add_sym(b, neg_gram(zh));
        f = add_v(f, neg_tmul_v(zh, wh));
        dn = neg_gram_c(yh);
        gn = neg_tmul_c(yh, zh);
        fnext = neg_tmul_v_c(yh, wh);
        ys[j] = ltmul_c(l, yh);
        zs[j] = ltmul(l, zh);
        ws[j] = ltmul_v(l, wh);
    }
    // The reduced system: row t is the separator's, its coupling to row t + 1 is gnᵀ, and what
    // the slice before it left for it comes from invocation t − 1 (first round); the rows
    // eliminated at the first level need their coupling to row t − 1 (second round).
    put_sym(XQ * t, dn);
    put_v(XQ * t + 21u, fnext);
    workgroupBarrier();
    if t > 0u {
        b = add_sym(b, get_sym(XQ * (t - 1u)));
        f = add_v(f, get_v(XQ * (t - 1u) + 21u));
    }
    workgroupBarrier();
    var cc = transpose6(gn);
    if t % 2u == 0u {
        put_m(36u * (t / 2u), cc);
    }
    workgroupBarrier();
    var a = M6(zero, zero, zero, zero);
    if t % 2u == 1u {
        a = transpose6(get_m(36u * (t / 2u)));
    }
    workgroupBarrier();
    // Cyclic reduction. A row eliminated at level s keeps L⁻¹ of its pivot in `le` and L⁻¹ A,
    // L⁻¹ C and L⁻¹ f in `a`, `cc`, `f`.
    var level = 0u;
    var le = L6(zero, zero, zero);
    var db_l = a;
    var db_r = a;
    for (var s = 1u; s < band_part.threads; s *= 2u) {
        let elim = t % (2u * s) == s;
        let keep = t % (2u * s) == 0u;
        if elim {
            le = chol6(b);
            a = lmul(le, a);
            cc = lmul(le, cc);
            f = lmul_v(le, f);
            let at = 48u * (t / (2u * s));
            put_m(at, neg_tmul(a, cc));
            put_v(at + 36u, neg_tmul_v(a, f));
            put_v(at + 42u, neg_tmul_v(cc, f));
            db_l = neg_gram(a);
            db_r = neg_gram(cc);
            level = s;
        }
        workgroupBarrier();
        if keep {
            if t >= s {
                let at = 48u * ((t - s) / (2u * s));
                a = transpose6(get_m(at));
                f = add_v(f, get_v(at + 42u));
            }
            let at = 48u * ((t + s) / (2u * s));
            cc = get_m(at);
            f = add_v(f, get_v(at + 36u));
        }
        workgroupBarrier();
        if elim {
            let at = 42u * (t / (2u * s));
            put_sym(at, db_l);
            put_sym(at + 21u, db_r);
        }
        workgroupBarrier();
        if keep {
            if t >= s {
                b = add_sym(b, get_sym(42u * ((t - s) / (2u * s)) + 21u));
            }
            b = add_sym(b, get_sym(42u * ((t + s) / (2u * s))));
        }
        workgroupBarrier();
    }
    // Back down: row 0, then the rows of each level from the top; `xch` holds the solutions.
    // x_e = L⁻ᵀ (L⁻¹ f − L⁻¹ A x_{e−s} − L⁻¹ C x_{e+s}).
    if t == 0u {
        let l = chol6(b);
        put_v(0u, ltmul_v(l, lmul_v(l, f)));
    }
    workgroupBarrier();
    for (var s = band_part.threads / 2u; s >= 1u; s /= 2u) {
        if level == s {
            var v = add_v(f, neg_mul_v(a, get_v(6u * (t - s))));
            if t + s < PT {
                v = add_v(v, neg_mul_v(cc, get_v(6u * (t + s))));
            }
            put_v(6u * t, ltmul_v(le, v));
        }
        workgroupBarrier();
    }
    // The interior, from the last element back.
    let xa = get_v(6u * t);
    var xn = V6(vec3<REAL>(), vec3<REAL>());
    if t + 1u < PT {
        xn = get_v(6u * (t + 1u));
    }
    for (var i = 1u; i < band_part.per_thread; i++) {
        let j = band_part.per_thread - i;
        let v = add_v(ws[j], add_v(neg_mul_v(ys[j], xn), neg_mul_v(zs[j], xa)));
        store_x(rod, j, t, v);
        xn = v;
    }
    store_x(rod, 0u, t, xa);
}
