// The Cholesky factor of a 3×3 block, shared by the banded solves (`banded_solve.wgsl`,
// `banded_partitioned.wgsl`): `banded.rs` puts this file before either, and fills in `REAL`.

// L⁻¹ of the Cholesky factor L of a symmetric positive semidefinite 3×3 block (its lower
// triangle is read), a non-positive pivot giving a zero row and column (`inverse_spd` of the
// CPU's `stiff/direct.rs` takes the same pivots).
fn chol_inv(a: mat3x3<REAL>) -> mat3x3<REAL> {
    // l[j][i]: the lower factor's entry (i, j) holds its inverse pivot on the diagonal.
    var l: mat3x3<REAL>;
    for (var j = 0u; j < 3u; j++) {
        var d = a[j][j];
        for (var k = 0u; k < j; k++) {
            d -= l[k][j] * l[k][j];
        }
        var inv = REAL(0.0);
        if d > REAL(0.0) {
            inv = REAL(1.0) / sqrt(d);
        }
        l[j][j] = inv;
        for (var i = j + 1u; i < 3u; i++) {
            var s = a[j][i];
            for (var k = 0u; k < j; k++) {
                s -= l[k][i] * l[k][j];
            }
            l[j][i] = s * inv;
        }
    }
    // m = L⁻¹ column by column (m[c][i]: entry (i, c)).
    var m: mat3x3<REAL>;
    for (var c = 0u; c < 3u; c++) {
        for (var i = c; i < 3u; i++) {
            var s = select(REAL(0.0), REAL(1.0), i == c);
            for (var k = c; k < i; k++) {
                s -= l[k][i] * m[c][k];
            }
            m[c][i] = s * l[i][i];
        }
    }
    return m;
}
