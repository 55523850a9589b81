// Small dense linear systems (a few unknowns: local fits), solved in place.
#pragma once

#include <algorithm>
#include <cmath>
#include <utility>

namespace vmap::detail {

// Solves the N x N system a x = b in place (Gaussian elimination with partial pivoting; x is left
// in b); false when a pivot is negligible against the matrix's scale (or the matrix is zero).
template <int N>
bool solve_small(double (&a)[N][N], double (&b)[N]) {
    double big = 0;
    for (int r = 0; r < N; ++r)
        for (int k = 0; k < N; ++k) big = std::max(big, std::fabs(a[r][k]));
    if (!(big > 0)) return false;
    for (int col = 0; col < N; ++col) {
        int piv = col;
        for (int r = col + 1; r < N; ++r)
            if (std::fabs(a[r][col]) > std::fabs(a[piv][col])) piv = r;
        if (!(std::fabs(a[piv][col]) > 1e-12 * big)) return false;
        if (piv != col) {
            for (int k = 0; k < N; ++k) std::swap(a[col][k], a[piv][k]);
            std::swap(b[col], b[piv]);
        }
        for (int r = col + 1; r < N; ++r) {
            const double f = a[r][col] / a[col][col];
            for (int k = col; k < N; ++k) a[r][k] -= f * a[col][k];
            b[r] -= f * b[col];
        }
    }
    for (int col = N - 1; col >= 0; --col) {
        double v = b[col];
        for (int k = col + 1; k < N; ++k) v -= a[col][k] * b[k];
        b[col] = v / a[col][col];
    }
    return true;
}

}  // namespace vmap::detail
