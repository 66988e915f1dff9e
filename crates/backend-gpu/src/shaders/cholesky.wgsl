// The Cholesky factor of a 3×3 block, shared by the banded solves (`banded_solve.wgsl`,
// `banded_partitioned.wgsl`): `banded.rs` puts this file before either, and fills in `REAL`.

// L⁻¹ of the Cholesky factor L of a symmetric positive semidefinite 3×3 block (its lower
// triangle is read), a non-positive pivot giving a zero row and column (`inverse_spd` of the
// CPU's `stiff/direct.rs` takes the same pivots).
fn chol_inv(a: mat3x3<REAL>) -> mat3x3<REAL> {
    // Written out rather than as loops over the entries: a loop index into a private matrix
    // puts it in local memory on NVIDIA GPUs. L(i, k) below the diagonal, inverse pivots on it.
    let zero = REAL(0.0);
    let d0 = a[0][0];
    let i0 = select(zero, REAL(1.0) / sqrt(d0), d0 > zero);
    let l10 = a[0][1] * i0;
    let l20 = a[0][2] * i0;
    let d1 = a[1][1] - l10 * l10;
    let i1 = select(zero, REAL(1.0) / sqrt(d1), d1 > zero);
    let l21 = (a[1][2] - l20 * l10) * i1;
    let d2 = a[2][2] - l20 * l20 - l21 * l21;
    let i2 = select(zero, REAL(1.0) / sqrt(d2), d2 > zero);
    // L⁻¹ column by column (forward substitution of the unit vectors).
    let m00 = i0;
    let m10 = (zero - l10 * m00) * i1;
    let m20 = (zero - l20 * m00 - l21 * m10) * i2;
    let m11 = i1;
    let m21 = (zero - l21 * m11) * i2;
    return mat3x3<REAL>(
        vec3<REAL>(m00, m10, m20),
        vec3<REAL>(zero, m11, m21),
        vec3<REAL>(zero, zero, i2),
    );
}
