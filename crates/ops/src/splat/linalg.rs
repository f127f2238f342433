//! The small fixed-size matrices of the projection: 3x3 and 2x3, row-major, in f64.

/// A 3x3 matrix, row-major.
pub(crate) type M3 = [[f64; 3]; 3];
/// A 2x3 matrix (the perspective Jacobian), row-major.
pub(crate) type M23 = [[f64; 3]; 2];
/// A symmetric 2x2 matrix `[[a, b], [b, c]]` as `[a, b, c]`.
pub(crate) type Sym2 = [f64; 3];

/// `a b`.
#[inline]
pub(crate) fn mul(a: &M3, b: &M3) -> M3 {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[i][0] * b[0][j] + a[i][1] * b[1][j] + a[i][2] * b[2][j]))
}

/// `a b^T`.
#[inline]
pub(crate) fn mul_t(a: &M3, b: &M3) -> M3 {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[i][0] * b[j][0] + a[i][1] * b[j][1] + a[i][2] * b[j][2]))
}

/// `a^T b`.
#[inline]
pub(crate) fn t_mul(a: &M3, b: &M3) -> M3 {
    [0, 1, 2].map(|i| [0, 1, 2].map(|j| a[0][i] * b[0][j] + a[1][i] * b[1][j] + a[2][i] * b[2][j]))
}

/// `j v j^T` for a symmetric `v`: a symmetric 2x2.
#[inline]
pub(crate) fn sandwich_23(j: &M23, v: &M3) -> Sym2 {
    let jv: [[f64; 3]; 2] =
        [0, 1].map(|r| [0, 1, 2].map(|c| j[r][0] * v[0][c] + j[r][1] * v[1][c] + j[r][2] * v[2][c]));
    let e = |r: usize, s: usize| jv[r][0] * j[s][0] + jv[r][1] * j[s][1] + jv[r][2] * j[s][2];
    [e(0, 0), e(0, 1), e(1, 1)]
}

/// `a^T x`.
#[inline]
pub(crate) fn t_apply(a: &M3, x: [f64; 3]) -> [f64; 3] {
    [0, 1, 2].map(|j| a[0][j] * x[0] + a[1][j] * x[1] + a[2][j] * x[2])
}
