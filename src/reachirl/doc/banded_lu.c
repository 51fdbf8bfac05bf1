/* reachirl: the banded LU solve of reachirl.doc.banded, compiled once per machine into reachirl's cache.
 *
 * LAPACK's dgbsv for one right-hand side: the LU factorisation with partial pivoting of dgbtf2, then the solve of
 * dgbtrs, on LAPACK's band storage (column-major, leading dimension 2*kl + ku + 1, kl rows of fill-in on top).
 * The operations are LAPACK's, in LAPACK's order, so that with the same fused multiply-adds as the BLAS it gives
 * the same bits (target_clones: fused where the processor has them, as OpenBLAS's kernels are). */
#include <math.h>
#include <stdlib.h>

#define AB(i, j) ab[(i) + (long)(j) * ldab] /* row i, column j of the band storage, 0-based */

#if defined(__x86_64__) && defined(__GNUC__)
__attribute__((target_clones("fma", "default")))
#endif
int reachirl_band_solve(int n, int kl, int ku, double *ab, double *b) {
    const int ldab = 2 * kl + ku + 1, kv = ku + kl;
    int info = 0, ju = 0;
    int *pivot = malloc(sizeof(int) * (size_t)(n > 0 ? n : 1));
    if (pivot == NULL) return -1; /* out of memory: no LAPACK info is negative but an argument's */
    /* the fill-in of the first columns starts at zero */
    for (int j = ku + 1; j < (kv < n ? kv : n); ++j)
        for (int i = kv - j + 1; i < kl; ++i) AB(i, j) = 0.0;
    for (int j = 0; j < n; ++j) {
        if (j + kv < n)
            for (int i = 0; i < kl; ++i) AB(i, j + kv) = 0.0;
        const int km = kl < n - 1 - j ? kl : n - 1 - j;
        int jp = 0; /* the pivot: the first entry of largest magnitude on or below the diagonal (idamax) */
        double largest = fabs(AB(kv, j));
        for (int i = 1; i <= km; ++i)
            if (fabs(AB(kv + i, j)) > largest) {
                largest = fabs(AB(kv + i, j));
                jp = i;
            }
        pivot[j] = j + jp;
        if (AB(kv + jp, j) == 0.0) {
            if (info == 0) info = j + 1; /* singular: factorised on, not solved (as dgbsv) */
            continue;
        }
        const int last = j + ku + jp < n - 1 ? j + ku + jp : n - 1;
        if (last > ju) ju = last;
        if (jp != 0) /* rows j and j + jp swapped, columns j .. ju */
            for (int c = 0; c <= ju - j; ++c) {
                const double t = AB(kv + jp - c, j + c);
                AB(kv + jp - c, j + c) = AB(kv - c, j + c);
                AB(kv - c, j + c) = t;
            }
        if (km > 0) {
            const double r = 1.0 / AB(kv, j); /* dscal by the reciprocal */
            for (int i = 1; i <= km; ++i) AB(kv + i, j) *= r;
            for (int c = 1; c <= ju - j; ++c) { /* dger: the rank-one update of the columns to the right */
                const double y = AB(kv - c, j + c);
                if (y != 0.0)
                    for (int i = 1; i <= km; ++i) AB(kv - c + i, j + c) -= AB(kv + i, j) * y;
            }
        }
    }
    if (info != 0) {
        free(pivot);
        return info;
    }
    for (int j = 0; j < n - 1; ++j) { /* L: the row interchanges and the unit lower triangle */
        const int lm = kl < n - 1 - j ? kl : n - 1 - j, l = pivot[j];
        if (l != j) {
            const double t = b[l];
            b[l] = b[j];
            b[j] = t;
        }
        const double y = b[j];
        if (y != 0.0)
            for (int i = 1; i <= lm; ++i) b[j + i] -= AB(kv + i, j) * y;
    }
    for (int j = n - 1; j >= 0; --j) { /* U: dtbsv, upper, column by column from the last */
        if (b[j] == 0.0) continue;
        b[j] /= AB(kv, j);
        const double t = b[j];
        const int lo = j - kv < 0 ? 0 : j - kv;
        for (int i = j - 1; i >= lo; --i) b[i] -= t * AB(kv - (j - i), j);
    }
    free(pivot);
    return 0;
}
