/* Morton codes and their stable order, for the compiled kernels: the same codes as the
 * NumPy functions named (float64 operations in their order, truncation as astype), and
 * the order of np.argsort(codes, kind="stable"), by a least-significant-digit radix sort.
 * Included after Python.h. */
#ifndef SCATTER_CMORTON_H
#define SCATTER_CMORTON_H

#include <math.h>
#include <stdint.h>
#include <stdlib.h>

/* the low 21 bits of x spread to every third bit (winding._spread, distance.spread_bits) */
static inline uint64_t spread21(uint64_t x)
{
    x &= 0x1FFFFF;
    x = (x | (x << 32)) & 0x1F00000000FFFFull;
    x = (x | (x << 16)) & 0x1F0000FF0000FFull;
    x = (x | (x << 8)) & 0x100F00F00F00F00Full;
    x = (x | (x << 4)) & 0x10C30C30C30C30C3ull;
    x = (x | (x << 2)) & 0x1249249249249249ull;
    return x;
}

/* distance.visit_order's codes of p (n, 3), all finite: 10 bits an axis over their box */
static inline void morton10(const double *p, int64_t n, uint64_t *code)
{
    double c0[3], c1[3], span[3];
    for (int k = 0; k < 3; k++)
        c0[k] = c1[k] = n ? p[k] : 0.0;
    for (int64_t i = 1; i < n; i++)
        for (int k = 0; k < 3; k++) {
            double v = p[3 * i + k];
            c0[k] = v < c0[k] ? v : c0[k], c1[k] = v > c1[k] ? v : c1[k];
        }
    for (int k = 0; k < 3; k++)
        span[k] = c1[k] > c0[k] ? c1[k] - c0[k] : 1.0;
    for (int64_t i = 0; i < n; i++) {
        uint64_t c[3];
        for (int k = 0; k < 3; k++) {
            int64_t cell = (int64_t)((p[3 * i + k] - c0[k]) / span[k] * 1024.0);
            c[k] = (uint64_t)(cell < 0 ? 0 : cell > 1023 ? 1023 : cell);
        }
        code[i] = (spread21(c[0]) << 2) | (spread21(c[1]) << 1) | spread21(c[2]);
    }
}

/* winding._morton's codes of p (n, 3): 21 bits an axis over the box of the finite rows
 * (the others: 0) */
static inline void morton21(const double *p, int64_t n, uint64_t *code)
{
    double lo[3] = {0, 0, 0}, hi[3] = {0, 0, 0};
    int any = 0;
    for (int64_t i = 0; i < n; i++) {
        const double *q = p + 3 * i;
        if (!(isfinite(q[0]) && isfinite(q[1]) && isfinite(q[2])))
            continue;
        for (int k = 0; k < 3; k++) {
            lo[k] = !any || q[k] < lo[k] ? q[k] : lo[k];
            hi[k] = !any || q[k] > hi[k] ? q[k] : hi[k];
        }
        any = 1;
    }
    for (int64_t i = 0; i < n; i++) {
        const double *q = p + 3 * i;
        int finite = isfinite(q[0]) && isfinite(q[1]) && isfinite(q[2]);
        uint64_t c[3];
        for (int k = 0; k < 3; k++) {
            double rel = ((finite ? q[k] : lo[k]) - lo[k]) / (hi[k] - lo[k]);
            rel = rel < 0.0 ? 0.0 : rel > 1.0 ? 1.0 : rel;
            rel = rel != rel ? 0.0 : rel;
            c[k] = (uint64_t)(rel * (2097152.0 - 1.0));
        }
        code[i] = any ? (spread21(c[0]) << 2) | (spread21(c[1]) << 1) | spread21(c[2]) : 0;
    }
}

/* order (n,): np.argsort(code, kind="stable") for codes below 2^bits; 0 when out of
 * memory. Each pass moves the keys with their indices (no reads of code[order[i]] from
 * far apart); the digits' counts are taken for every pass in one read, and a pass whose
 * digit is the same for every key is skipped. */
#define ORDER_DIGIT 11
#define ORDER_PASSES 6 /* 6 * 11 bits >= 63 */
static inline int stable_order(const uint64_t *code, int64_t n, int bits, int64_t *order)
{
    size_t size = (size_t)(n > 0 ? n : 1);
    uint64_t *keys = malloc(sizeof(uint64_t) * 2 * size);
    int64_t *tmp = malloc(sizeof(int64_t) * size);
    int64_t(*count)[(1 << ORDER_DIGIT) + 1] = calloc(ORDER_PASSES, sizeof *count);
    int ok = keys && tmp && count;
    if (ok) {
        const int64_t mask = (1 << ORDER_DIGIT) - 1;
        int passes = (bits + ORDER_DIGIT - 1) / ORDER_DIGIT;
        passes = passes < ORDER_PASSES ? passes : ORDER_PASSES;
        for (int64_t i = 0; i < n; i++) {
            uint64_t c = code[i];
            for (int p = 0; p < passes; p++)
                count[p][((c >> (p * ORDER_DIGIT)) & mask) + 1]++;
        }
        uint64_t *kf = keys, *kt = keys + size;
        int64_t *of = order, *ot = tmp;
        for (int64_t i = 0; i < n; i++)
            kf[i] = code[i], of[i] = i;
        for (int p = 0; p < passes; p++) {
            int64_t *c = count[p];
            if (n && c[((kf[0] >> (p * ORDER_DIGIT)) & mask) + 1] == n)
                continue; /* one digit for all: the order stays */
            for (int64_t d = 0; d < mask + 1; d++)
                c[d + 1] += c[d];
            for (int64_t i = 0; i < n; i++) {
                int64_t to = c[(kf[i] >> (p * ORDER_DIGIT)) & mask]++;
                kt[to] = kf[i], ot[to] = of[i];
            }
            uint64_t *ks = kf;
            kf = kt, kt = ks;
            int64_t *os = of;
            of = ot, ot = os;
        }
        if (of != order)
            for (int64_t i = 0; i < n; i++)
                order[i] = of[i];
    }
    free(keys), free(tmp), free(count);
    return ok;
}

#endif
