/* Compiled pair graph and greedy thinning: the same results as the NumPy path (pairs.py, greedy.py).
 *
 * grid() sorts points by cell (side >= reach) and holds their coordinates axis by axis in
 * cell order. pairs() and greedy() visit the cells in key order. The 27 cells around a
 * cell are nine runs of positions, one per column (dx, dy), since the cells z - 1 .. z + 1
 * have consecutive keys; a table over the box of cells (or, for a box too large, nine
 * cursors moving forward in the sorted cell list) finds them.
 * A pair is found once, from its earlier point, in the runs after it.
 * greedy() takes a maximal independent set of the pairs shorter than a radius, least
 * crowded first, in rounds: one pass on all threads sums each point's crowding and lists
 * its neighbours (6 bytes a neighbour; past MOST_LISTED a point they are found again in
 * the grid when needed); each round then keeps, in order of crowding, the least crowded
 * share of the undecided points that are not yet dropped, drops their neighbours, and
 * takes the dropped out of their own neighbours' crowding. Distances and
 * crowding are computed with the same float64 operations as the NumPy code (built with
 * -ffp-contract=off; the AVX-512 paths multiply and add separately too) and crowding is a
 * sum of whole numbers, so neither the order pairs are found in nor the path changes a
 * result.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include "_ckernel.h"
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "_cthreads.h"
#include <stdio.h>

/* Shared with the NumPy path: exported as module attributes, which tests/test_native.py
 * holds equal to pairs.BITS, pairs.MAX_CELLS and greedy.CROWD_SCALE. */
#define BITS 21
#define MAX_CELLS ((1 << BITS) - 8)
#define CROWD_SCALE 65536.0

static uint64_t pack(int64_t x, int64_t y, int64_t z)
{
    return ((uint64_t)x << (2 * BITS)) | ((uint64_t)y << BITS) | (uint64_t)z;
}

/* The kernels' arrays come from a pool that keeps what they give back for their next
 * call, up to POOL_BYTES: on this host freshly touched memory costs more than much of the
 * work done on it (a page fault per 4 kB; about a second per GB). A block carries its
 * size in a header before it. */
#define POOL_SLOTS 32
#define POOL_BYTES ((size_t)128 << 20)
#define POOL_SMALLEST 65536
#define HEAD 64
static void *pool[POOL_SLOTS];
static size_t pooled;
static pthread_mutex_t pool_lock = PTHREAD_MUTEX_INITIALIZER;

static size_t capacity(void *p)
{
    return *(size_t *)((char *)p - HEAD);
}

/* size bytes: the smallest pooled block that fits without wasting more than its size,
 * else a new one. */
static void *take(size_t size)
{
    int best = -1;
    pthread_mutex_lock(&pool_lock);
    for (int k = 0; k < POOL_SLOTS; k++)
        if (pool[k] && capacity(pool[k]) >= size && capacity(pool[k]) <= 2 * size + POOL_SMALLEST &&
            (best < 0 || capacity(pool[k]) < capacity(pool[best])))
            best = k;
    void *p = best >= 0 ? pool[best] : NULL;
    if (p) {
        pool[best] = NULL;
        pooled -= capacity(p);
    }
    pthread_mutex_unlock(&pool_lock);
    if (p)
        return p;
    char *raw = malloc(size + HEAD);
    if (!raw)
        return NULL;
    *(size_t *)raw = size;
    return raw + HEAD;
}

static void *take_zeroed(size_t size)
{
    void *p = take(size);
    if (p)
        memset(p, 0, size);
    return p;
}

static void give(void *p)
{
    if (!p)
        return;
    size_t size = capacity(p);
    int kept = 0;
    pthread_mutex_lock(&pool_lock);
    for (int k = 0; k < POOL_SLOTS && !kept && size >= POOL_SMALLEST && pooled + size <= POOL_BYTES; k++)
        if (!pool[k]) {
            pool[k] = p;
            pooled += size;
            kept = 1;
        }
    pthread_mutex_unlock(&pool_lock);
    if (!kept)
        free((char *)p - HEAD);
}

/* p (from take, holding used bytes) grown to size bytes, or NULL (p still held). */
static void *grow(void *p, size_t used, size_t size)
{
    void *q = take(size);
    if (q && p) {
        memcpy(q, p, used);
        give(p);
    }
    return q;
}

static void free_buffer(PyObject *capsule)
{
    give(PyCapsule_GetPointer(capsule, NULL));
}

/* A 1-D array over ``data`` (from take), which it gives back when it goes. */
static PyObject *owned_array(int type, npy_intp n, void *data)
{
    npy_intp dims[1] = {n};
    PyObject *capsule = PyCapsule_New(data, NULL, free_buffer);
    if (!capsule) {
        give(data);
        return NULL;
    }
    PyObject *arr = PyArray_SimpleNewFromData(1, dims, type, data);
    if (!arr) {
        Py_DECREF(capsule);
        return NULL;
    }
    if (PyArray_SetBaseObject((PyArrayObject *)arr, capsule) < 0) { /* steals capsule */
        Py_DECREF(arr);
        return NULL;
    }
    return arr;
}

/* Sort (key, idx) pairs by key, stably: LSD radix, a byte at a time, skipping the bytes
 * all keys share. */
static int radix_sort(uint64_t *key, int32_t *idx, int64_t n)
{
    uint64_t *k2 = take((n ? n : 1) * sizeof(uint64_t));
    int32_t *i2 = take((n ? n : 1) * sizeof(int32_t));
    if (!k2 || !i2) {
        give(k2);
        give(i2);
        return 0;
    }
    uint64_t differ = 0;
    for (int64_t i = 1; i < n; i++)
        differ |= key[i] ^ key[0];
    for (int shift = 0; shift < 64; shift += 8) {
        if (!((differ >> shift) & 0xff))
            continue;
        int64_t count[257] = {0};
        for (int64_t i = 0; i < n; i++)
            count[((key[i] >> shift) & 0xff) + 1]++;
        for (int b = 0; b < 256; b++)
            count[b + 1] += count[b];
        for (int64_t i = 0; i < n; i++) {
            int64_t to = count[(key[i] >> shift) & 0xff]++;
            k2[to] = key[i];
            i2[to] = idx[i];
        }
        memcpy(key, k2, n * sizeof(uint64_t));
        memcpy(idx, i2, n * sizeof(int32_t));
    }
    give(k2);
    give(i2);
    return 1;
}

/* A growing list of pairs (i, j, d). */
typedef struct {
    int64_t *i, *j;
    double *d;
    int64_t size, cap;
} Pairs;

/* *p (from take, holding used bytes) grown to size bytes; 0, *p unchanged, when out of
 * memory. */
static int grow_array(void **p, size_t used, size_t size)
{
    void *q = grow(*p, used, size);
    if (q)
        *p = q;
    return q != NULL;
}

/* Room for more entries after size, in a list of cap: doubled from cap, or from first. */
static int64_t room_for(int64_t size, int64_t cap, int64_t more, int64_t first)
{
    cap = cap ? cap : first;
    while (cap < size + more)
        cap *= 2;
    return cap;
}

static int pairs_reserve(Pairs *e, int64_t more)
{
    if (e->size + more <= e->cap)
        return 1;
    int64_t cap = room_for(e->size, e->cap, more, 1 << 12);
    if (!grow_array((void **)&e->i, e->size * sizeof(int64_t), cap * sizeof(int64_t)) ||
        !grow_array((void **)&e->j, e->size * sizeof(int64_t), cap * sizeof(int64_t)) ||
        !grow_array((void **)&e->d, e->size * sizeof(double), cap * sizeof(double)))
        return 0;
    e->cap = cap;
    return 1;
}

/* A grid built by grid(), as C arrays. */
typedef struct {
    const int64_t *order;      /* (a,) active number at each position */
    const double *x, *y, *z;   /* (a,) coordinates, in cell order */
    const uint64_t *ukey;      /* (cells,) cell keys, ascending */
    const int64_t *cell_start; /* (cells + 1,) first position of each cell */
    int64_t a, cells;
} Grid;

/* For each cell, the positions of the 27 cells around it, as nine ranges (one per column
 * dx, dy: the cells z - 1 .. z + 1 are consecutive keys): range k of cell c is positions
 * ranges[18 c + 2 k] .. ranges[18 c + 2 k + 1] - 1. Cells are visited in key order, so
 * each column's search goes on from where it stopped. */
static void column_ranges_by_search(const Grid *g, int32_t *ranges)
{
    int64_t cursor[9] = {0};
    for (int64_t c = 0; c < g->cells; c++) {
        for (int col = 0; col < 9; col++) {
            int64_t dx = col / 3 - 1, dy = col % 3 - 1;
            uint64_t first = g->ukey[c] + (uint64_t)(dx * ((int64_t)1 << (2 * BITS)) + dy * ((int64_t)1 << BITS) - 1);
            int64_t t = cursor[col];
            while (t < g->cells && g->ukey[t] < first)
                t++;
            cursor[col] = t;
            int64_t end = t;
            while (end < g->cells && g->ukey[end] <= first + 2)
                end++;
            ranges[18 * c + 2 * col] = (int32_t)g->cell_start[t];
            ranges[18 * c + 2 * col + 1] = (int32_t)g->cell_start[end];
        }
    }
}

/* column_ranges through a table over the box of cells (one cell wider on every side, two
 * above in z): for each place, how many cells have a smaller key. The search loops
 * branch unpredictably; this has no branches, and fills the table in two passes. Returns
 * 0, doing nothing, when the box is too large for its cells. */
static int column_ranges_by_table(const Grid *g, int32_t *ranges)
{
    const uint64_t mask = ((uint64_t)1 << BITS) - 1;
    int64_t lo[3] = {(int64_t)(g->ukey[0] >> (2 * BITS)), INT64_MAX, INT64_MAX}, hi[3] = {0, 0, 0};
    hi[0] = (int64_t)(g->ukey[g->cells - 1] >> (2 * BITS));
    for (int64_t c = 0; c < g->cells; c++) {
        int64_t y = (int64_t)((g->ukey[c] >> BITS) & mask), z = (int64_t)(g->ukey[c] & mask);
        lo[1] = y < lo[1] ? y : lo[1];
        hi[1] = y > hi[1] ? y : hi[1];
        lo[2] = z < lo[2] ? z : lo[2];
        hi[2] = z > hi[2] ? z : hi[2];
    }
    int64_t nx = hi[0] - lo[0] + 3, ny = hi[1] - lo[1] + 3, nz = hi[2] - lo[2] + 4;
    int64_t most = 64 * g->cells + (1 << 16);
    if (nx * ny > most || nx * ny * nz > most)
        return 0;
    int32_t *below = take_zeroed(nx * ny * nz * sizeof(int32_t));
    if (!below)
        return 0;
#define PLACE(x, y, z) ((((x) - lo[0] + 1) * ny + ((y) - lo[1] + 1)) * nz + ((z) - lo[2] + 1))
    for (int64_t c = 0; c < g->cells; c++)
        below[PLACE((int64_t)(g->ukey[c] >> (2 * BITS)), (int64_t)((g->ukey[c] >> BITS) & mask),
                    (int64_t)(g->ukey[c] & mask))] = 1;
    int32_t seen = 0;
    for (int64_t p = 0; p < nx * ny * nz; p++) {
        int32_t here = below[p];
        below[p] = seen;
        seen += here;
    }
    for (int64_t c = 0; c < g->cells; c++) {
        int64_t x = (int64_t)(g->ukey[c] >> (2 * BITS)), y = (int64_t)((g->ukey[c] >> BITS) & mask);
        int64_t z = (int64_t)(g->ukey[c] & mask);
        for (int col = 0; col < 9; col++) {
            int64_t p = PLACE(x + col / 3 - 1, y + col % 3 - 1, z - 1);
            ranges[18 * c + 2 * col] = (int32_t)g->cell_start[below[p]];
            ranges[18 * c + 2 * col + 1] = (int32_t)g->cell_start[below[p + 3]];
        }
    }
#undef PLACE
    give(below);
    return 1;
}

static void column_ranges(const Grid *g, int32_t *ranges)
{
    if (g->cells && !column_ranges_by_table(g, ranges))
        column_ranges_by_search(g, ranges);
}

/* The number of points in the 27 cells of ranges r (18,). */
static int64_t around_count(const int32_t *r)
{
    int64_t n = 0;
    for (int k = 0; k < 9; k++)
        n += r[2 * k + 1] - r[2 * k];
    return n;
}

static int get_grid(PyObject *args, Grid *g, double *reach, double *radius, PyObject **okept, Py_ssize_t *share,
                    Py_ssize_t *least, int *threads)
{
    PyObject *o[4];
    if (!PyArg_ParseTuple(args, okept ? "OOOOddOnni" : "OOOOd", &o[0], &o[1], &o[2], &o[3], reach, radius, okept,
                          share, least, threads))
        return 0;
    PyArrayObject *a[4], *kept;
    if (!get(o[0], NPY_INT64, -1, &a[0], "grid order"))
        return 0;
    g->a = PyArray_SIZE(a[0]);
    if (!get(o[2], NPY_UINT64, -1, &a[2], "grid ukey"))
        return 0;
    g->cells = PyArray_SIZE(a[2]);
    if (!get(o[1], NPY_FLOAT64, 3 * g->a, &a[1], "grid xyz") || !get(o[3], NPY_INT64, g->cells + 1, &a[3], "grid cell_start") ||
        (okept && !get(*okept, NPY_BOOL, g->a, &kept, "kept")))
        return 0;
    g->order = PyArray_DATA(a[0]);
    g->x = PyArray_DATA(a[1]);
    g->ukey = PyArray_DATA(a[2]);
    g->cell_start = PyArray_DATA(a[3]);
    g->y = g->x + g->a;
    g->z = g->y + g->a;
    if (g->cell_start[g->cells] != g->a || g->a >= INT32_MAX) {
        PyErr_Format(PyExc_ValueError, "grid arrays do not match");
        return 0;
    }
    return 1;
}

/* The fine cell of point p, as pairs.Frame.keys: floor((p - lo) / size) + 2, clipped. */
static inline void fine_cell(const double *p, const double *lo, double size, int64_t f[3])
{
    for (int k = 0; k < 3; k++) {
        double v = (p[k] - lo[k]) / size;
        int64_t c = (v >= 0 ? (int64_t)v : (int64_t)floor(v)) + 2; /* floor, cheaply when v >= 0 */
        f[k] = c < 0 ? 0 : (c > MAX_CELLS ? MAX_CELLS : c);
    }
}

PyDoc_STRVAR(grid_doc,
"grid(points, lo, size, cap) -> (active, order, xyz, ukey, cell_start)\n\n"
"points (n, 3) float64 into cells of two fine cells a side, the fine cells (side size)\n"
"from corner lo (3,) float64 as pairs.Frame. With cap > 0 only the first cap points\n"
"(input order) of each fine cell are active, else all. active (a,) int64: their input\n"
"indices, ascending, which numbers them 0..a-1. They are held in cell order: position s\n"
"is active point order[s] (int64) at xyz[:, s] ((3, a) float64); cell c has the positions\n"
"cell_start[c] .. cell_start[c + 1] - 1 and key ukey[c] (uint64, ascending).");

static PyObject *grid(PyObject *self, PyObject *args)
{
    PyObject *opts, *olo;
    double size;
    int cap;
    if (!PyArg_ParseTuple(args, "OOdi", &opts, &olo, &size, &cap))
        return NULL;
    PyArrayObject *apts, *alo;
    npy_intp rows;
    if (!get_rows(opts, NPY_FLOAT64, 3, &apts, &rows, "points") || !get(olo, NPY_FLOAT64, 3, &alo, "lo"))
        return NULL;
    const double *pts = PyArray_DATA(apts);
    const double *lo = PyArray_DATA(alo);
    int64_t n = rows, m = n ? n : 1;
    if (n >= INT32_MAX)
        return PyErr_Format(PyExc_ValueError, "too many points for the compiled grid");

    int ok = 0;
    int64_t a = 0, cells = 0;
    uint64_t *key = take(m * sizeof(uint64_t)), *ukey = take(m * sizeof(uint64_t));
    int32_t *perm = take(m * sizeof(int32_t)); /* n < 2^31 */
    int64_t *number = take(m * sizeof(int64_t));
    int64_t *cell_start = take((m + 1) * sizeof(int64_t)), *active = take(m * sizeof(int64_t));
    int64_t *order = take(m * sizeof(int64_t));
    unsigned char *sub = take(m);
    double *xyz = take(3 * m * sizeof(double));
    if (!key || !ukey || !perm || !number || !cell_start || !active || !order || !sub || !xyz)
        goto done;
    Py_BEGIN_ALLOW_THREADS
    /* A cell is two fine cells a side (side >= reach); ``sub`` says which of its eight.
       Cells are sorted by a compact key, in the order of their packed keys (x, then y,
       then z), so the radix sort has few bytes to go through. */
    /* cells are monotone in the coordinates: the extreme cells are those of the extremes */
    double pmin[3] = {0, 0, 0}, pmax[3] = {0, 0, 0};
    for (int64_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            double v = pts[3 * i + k];
            pmin[k] = i == 0 || v < pmin[k] ? v : pmin[k];
            pmax[k] = i == 0 || v > pmax[k] ? v : pmax[k];
        }
    int64_t cmin[3], cmax[3], f[3];
    fine_cell(pmin, lo, size, cmin);
    fine_cell(pmax, lo, size, cmax);
    for (int k = 0; k < 3; k++) {
        cmin[k] = (cmin[k] >> 1) + 1;
        cmax[k] = (cmax[k] >> 1) + 1;
    }
    int64_t ny = n ? cmax[1] - cmin[1] + 1 : 1, nz = n ? cmax[2] - cmin[2] + 1 : 1;
    for (int64_t i = 0; i < n; i++) {
        fine_cell(pts + 3 * i, lo, size, f);
        key[i] = (uint64_t)((((f[0] >> 1) + 1 - cmin[0]) * ny + ((f[1] >> 1) + 1 - cmin[1])) * nz +
                            ((f[2] >> 1) + 1 - cmin[2]));
        sub[i] = (unsigned char)(((f[0] & 1) << 2) | ((f[1] & 1) << 1) | (f[2] & 1));
        perm[i] = (int32_t)i;
    }
    if (!radix_sort(key, perm, n))
        goto unlock;
    /* the cap: rank in input order within each fine cell (the sort is stable); a point
       past the cap is marked in the spare high bit of its ``sub``. Most point sets have
       none: then every point is active under its own number, and ``number`` is unused. */
    int over = 0;
    int64_t seen[8] = {0};
    for (int64_t s = 0; cap > 0 && s < n; s++) {
        if (s > 0 && key[s] != key[s - 1])
            memset(seen, 0, sizeof(seen));
        if (seen[sub[perm[s]]]++ >= cap) {
            sub[perm[s]] |= 0x80;
            over = 1;
        }
    }
    for (int64_t i = 0; i < n; i++) {
        if (!over)
            active[a++] = i;
        else if (sub[i] & 0x80)
            number[i] = -1;
        else {
            active[a] = i;
            number[i] = a++;
        }
    }
    int64_t k = 0;
    uint64_t last = 0;
    for (int64_t s = 0; s < n; s++) {
        int64_t i = perm[s];
        if (over && number[i] < 0)
            continue;
        if (k == 0 || key[s] != last) {
            last = key[s];
            int64_t z = (int64_t)(last % (uint64_t)nz), y = (int64_t)(last / (uint64_t)nz % (uint64_t)ny);
            int64_t x = (int64_t)(last / (uint64_t)nz / (uint64_t)ny);
            ukey[cells] = pack(x + cmin[0], y + cmin[1], z + cmin[2]);
            cell_start[cells++] = k;
        }
        xyz[k] = pts[3 * i];
        xyz[a + k] = pts[3 * i + 1];
        xyz[2 * a + k] = pts[3 * i + 2];
        order[k++] = over ? number[i] : i;
    }
    cell_start[cells] = a;
    ok = 1;
unlock:
    Py_END_ALLOW_THREADS
done:
    give(key);
    give(perm);
    give(number);
    give(sub);
    if (!ok) {
        give(ukey);
        give(cell_start);
        give(active);
        give(order);
        give(xyz);
        return PyErr_NoMemory();
    }
    PyObject *oxyz = owned_array(NPY_FLOAT64, 3 * a, xyz);
    if (!oxyz)
        return NULL;
    npy_intp dims[2] = {3, a};
    PyArray_Dims shape = {dims, 2};
    PyObject *xyz2 = PyArray_Newshape((PyArrayObject *)oxyz, &shape, NPY_CORDER);
    Py_DECREF(oxyz);
    return Py_BuildValue("NNNNN", owned_array(NPY_INT64, a, active), owned_array(NPY_INT64, a, order), xyz2,
                         owned_array(NPY_UINT64, cells, ukey), owned_array(NPY_INT64, cells + 1, cell_start));
}

/* The points of positions t0 .. t1 - 1 closer to position s than sqrt(r2): their positions
 * go on at, their squared distances on d2, from entry w on; returns the new end. No
 * branches: the distances are computed in one vectorised loop, then kept or passed over. */
static int64_t hits_in(const Grid *g, int64_t s, int64_t t0, int64_t t1, double r2, double *restrict d2,
                       int32_t *restrict at, int64_t w, double *restrict tmp)
{
    double px = g->x[s], py = g->y[s], pz = g->z[s];
    const double *restrict x = g->x + t0, *restrict y = g->y + t0, *restrict z = g->z + t0;
    int64_t n = t1 - t0;
    for (int64_t l = 0; l < n; l++) {
        double dx = px - x[l], dy = py - y[l], dz = pz - z[l];
        double e = dx * dx + dy * dy; /* pairs.self_pairs' order of operations */
        tmp[l] = e + dz * dz;
    }
    for (int64_t l = 0; l < n; l++) {
        at[w] = (int32_t)(t0 + l);
        d2[w] = tmp[l];
        w += tmp[l] < r2;
    }
    return w;
}

#if defined(__x86_64__) && defined(__GNUC__)
#include <immintrin.h>
/* hits_in with AVX-512: eight distances at a time, and the hits packed in registers
 * (compress to memory is slow on some cores). The same float64 operations in the same
 * order, so the same hits; it may write up to eight entries past the new end. */
__attribute__((target("avx512f,avx512vl"))) static int64_t
hits_in_avx512(const Grid *g, int64_t s, int64_t t0, int64_t t1, double r2, double *restrict d2,
               int32_t *restrict at, int64_t w, double *restrict tmp)
{
    (void)tmp;
    __m512d px = _mm512_set1_pd(g->x[s]), py = _mm512_set1_pd(g->y[s]), pz = _mm512_set1_pd(g->z[s]);
    __m512d limit = _mm512_set1_pd(r2);
    __m256i at8 = _mm256_add_epi32(_mm256_set1_epi32((int32_t)t0), _mm256_setr_epi32(0, 1, 2, 3, 4, 5, 6, 7));
    for (int64_t t = t0; t < t1; t += 8) {
        __mmask8 live = t1 - t >= 8 ? 0xff : (__mmask8)((1u << (t1 - t)) - 1);
        __m512d dx = _mm512_sub_pd(px, _mm512_maskz_loadu_pd(live, g->x + t));
        __m512d dy = _mm512_sub_pd(py, _mm512_maskz_loadu_pd(live, g->y + t));
        __m512d dz = _mm512_sub_pd(pz, _mm512_maskz_loadu_pd(live, g->z + t));
        __m512d e = _mm512_add_pd(_mm512_mul_pd(dx, dx), _mm512_mul_pd(dy, dy));
        __m512d d = _mm512_add_pd(e, _mm512_mul_pd(dz, dz));
        __mmask8 hit = _mm512_mask_cmp_pd_mask(live, d, limit, _CMP_LT_OQ);
        _mm512_storeu_pd(d2 + w, _mm512_maskz_compress_pd(hit, d));
        _mm256_storeu_si256((__m256i *)(at + w), _mm256_maskz_compress_epi32(hit, at8));
        w += __builtin_popcount(hit);
        at8 = _mm256_add_epi32(at8, _mm256_set1_epi32(8));
    }
    return w;
}
#endif

typedef int64_t (*HitsIn)(const Grid *, int64_t, int64_t, int64_t, double, double *, int32_t *, int64_t, double *);
static HitsIn find_hits = hits_in;

/* Room for the hits of one point among its 27 cells. */
typedef struct {
    double *d2, *tmp;
    double *weight;
    int32_t *at;
    uint16_t *lift;
} Scratch;

static int scratch_init(Scratch *b, int64_t most)
{
    most += 16; /* room for whole vectors past the end */
    b->d2 = malloc(most * sizeof(double));
    b->tmp = malloc(most * sizeof(double));
    b->at = malloc(most * sizeof(int32_t));
    b->weight = malloc(most * sizeof(double));
    b->lift = malloc(most * sizeof(uint16_t));
    return b->d2 && b->tmp && b->at && b->weight && b->lift;
}

static void scratch_free(Scratch *b)
{
    free(b->d2);
    free(b->tmp);
    free(b->at);
    free(b->weight);
    free(b->lift);
}

/* The points after position s (cell ranges r) closer than sqrt(r2), into b: those after it
 * in its own column (its cell and the one above), then in the columns (0, 1), (1, -1),
 * (1, 0) and (1, 1), which come later in key order. Returns how many. */
static int64_t later_hits(const Grid *g, const int32_t *r, int64_t s, double r2, Scratch *b)
{
    int64_t hits = find_hits(g, s, s + 1, r[9], r2, b->d2, b->at, 0, b->tmp);
    for (int col = 5; col < 9; col++)
        hits = find_hits(g, s, r[2 * col], r[2 * col + 1], r2, b->d2, b->at, hits, b->tmp);
    return hits;
}

/* The most points in the 27 cells of any cell. */
static int64_t most_around(const Grid *g, const int32_t *ranges)
{
    int64_t most = 0;
    for (int64_t c = 0; c < g->cells; c++)
        most = around_count(ranges + 18 * c) > most ? around_count(ranges + 18 * c) : most;
    return most;
}

PyDoc_STRVAR(pairs_doc,
"pairs(order, xyz, ukey, cell_start, reach) -> (i, j, d)\n\n"
"Every pair of a grid() closer than reach: i < j (int64) active numbers, d (float64)\n"
"their distance, as pairs.self_pairs (in another order).");

static PyObject *pairs(PyObject *self, PyObject *args)
{
    Grid g;
    double reach, unused = 0;
    if (!get_grid(args, &g, &reach, &unused, NULL, NULL, NULL, NULL))
        return NULL;
    int ok = 0;
    Pairs e = {0};
    Scratch b = {0};
    int32_t *ranges = take((18 * g.cells + 1) * sizeof(int32_t));
    if (!ranges)
        return PyErr_NoMemory();
    Py_BEGIN_ALLOW_THREADS
    double r2 = reach * reach;
    column_ranges(&g, ranges);
    if (!scratch_init(&b, most_around(&g, ranges)))
        goto unlock;
    for (int64_t c = 0; c < g.cells; c++)
        for (int64_t s = g.cell_start[c]; s < g.cell_start[c + 1]; s++) {
            int64_t hits = later_hits(&g, ranges + 18 * c, s, r2, &b);
            if (!pairs_reserve(&e, hits))
                goto unlock;
            for (int64_t h = 0; h < hits; h++) {
                int64_t i = g.order[s], j = g.order[b.at[h]];
                e.i[e.size] = i < j ? i : j;
                e.j[e.size] = i < j ? j : i;
                e.d[e.size++] = sqrt(b.d2[h]);
            }
        }
    ok = pairs_reserve(&e, 1); /* an array needs a buffer, even an empty one */
unlock:
    Py_END_ALLOW_THREADS
    give(ranges);
    scratch_free(&b);
    if (!ok) {
        give(e.i);
        give(e.j);
        give(e.d);
        return PyErr_NoMemory();
    }
    return Py_BuildValue("NNN", owned_array(NPY_INT64, e.size, e.i), owned_array(NPY_INT64, e.size, e.j),
                         owned_array(NPY_FLOAT64, e.size, e.d));
}

/* floor(v) for 0 <= v < 2^52, in operations that vectorise: adding and taking away 2^52
 * rounds v to a whole number, which is one too high when it rounded up. */
static inline double floor_weight(double v)
{
    double t = (v + 4503599627370496.0) - 4503599627370496.0;
    return t - (t > v ? 1.0 : 0.0);
}

/* The crowding weight floor((1 - d * scale) * CROWD_SCALE) of each squared distance
 * d2 (n,) into weight (n,), d = sqrt(d2) < radius = 1 / (2 scale). */
__attribute__((target_clones("avx512f", "default"))) static void
weigh(const double *restrict d2, double *restrict weight, int64_t n, double scale)
{
    for (int64_t h = 0; h < n; h++) /* vectorised */
        weight[h] = floor_weight((1.0 - sqrt(d2[h]) * scale) * CROWD_SCALE);
}

/* What the greedy's passes share. */
typedef struct {
    const Grid *g;
    const int32_t *ranges; /* (cells, 18) column_ranges */
    int64_t most;          /* the most positions around one cell */
    double r2;             /* below it a squared distance is an edge of the greedy's graph */
    double radius;         /* the thinning radius, for the crowding weights */
} Greedy;

/* Crowding weights are whole numbers from 32767 (d just under the radius, after rounding)
 * to 65536 (d = 0): stored less LIFT, they fit in 16 bits. */
#define LIFT 32000

/* Positions a piece of the crowding pass holds, about: the pieces depend on the point set
 * alone, never on the threads, so neither does anything the pass decides. */
#define PIECE_POINTS 16384

/* One piece of the pairs: those whose earlier point is in cells c0 .. c1 - 1. Their weights
 * are added to the crowding of their earlier ends at once, and to that of their later ends
 * once all pieces are done, from the lists (or at once, atomically, for pairs past the
 * budget, which are not listed): sums of whole numbers, so their order changes nothing. */
typedef struct {
    const Greedy *w;
    int64_t c0, c1;
    int64_t *crowd;  /* (a,) shared: the sums */
    int32_t *degree; /* (a,) shared: how many of the backward rows' pairs are in place */
    int32_t *later;  /* (a,) shared: how many pairs each of this piece's positions found */
    int64_t *first;  /* (a,) shared: where they start in to and lift */
    int32_t *to;     /* (size,) the later end of each pair found, in position order */
    uint16_t *lift;  /* (size,) its weight less LIFT */
    int64_t size, cap;
    int64_t *listed; /* shared: the pairs found so far by all pieces (atomic) */
    int64_t budget;  /* list no more pairs than this in all; past it, over is set and the lists stop */
    int shared;      /* pieces run on more than one thread: crowd and listed take atomic adds */
    int over;
    const int64_t *back; /* the backward rows to fill (see Rows) */
    int32_t *bnbr;
    uint16_t *blift;
    int ok;
} Job;

/* *p += v, atomic when the pieces run on several threads; the old value */
static inline int64_t add64(int shared, int64_t *p, int64_t v)
{
    if (shared)
        return __atomic_fetch_add(p, v, __ATOMIC_RELAXED);
    int64_t old = *p;
    *p = old + v;
    return old;
}

static int job_reserve(Job *job, int64_t more)
{
    if (job->size + more <= job->cap)
        return 1;
    int64_t cap = room_for(job->size, job->cap, more, 1 << 14);
    if (!grow_array((void **)&job->to, job->size * sizeof(int32_t), cap * sizeof(int32_t)) ||
        !grow_array((void **)&job->lift, job->size * sizeof(uint16_t), cap * sizeof(uint16_t)))
        return 0;
    job->cap = cap;
    return 1;
}

/* The pairs whose earlier point is in the piece's cells, with their crowding: each pair's
 * weight floor((1 - d / (2 radius)) * CROWD_SCALE) goes to both its ends. */
static void crowd_job(void *jobs, int k, int count)
{
    Job *job = (Job *)jobs + k;
    (void)count;
    const Greedy *w = job->w;
    const Grid *g = w->g;
    int64_t *crowd = job->crowd;
    double scale = 1.0 / (2.0 * w->radius);
    Scratch b;
    job->ok = scratch_init(&b, w->most);
    /* (worth no room of its own: the piece's points, as a whole list would take) */
    job->ok = job->ok && job_reserve(job, 12 * (g->cell_start[job->c1] - g->cell_start[job->c0]));
    for (int64_t c = job->c0; job->ok && c < job->c1; c++) {
        const int32_t *r = w->ranges + 18 * c;
        for (int64_t s = g->cell_start[c]; s < g->cell_start[c + 1]; s++) {
            int64_t hits = later_hits(g, r, s, w->r2, &b);
            job->over |= add64(job->shared, job->listed, hits) + hits > job->budget;
            if (!job->over && !job_reserve(job, hits)) {
                job->ok = 0;
                break;
            }
            weigh(b.d2, b.weight, hits, scale);
            int64_t sum = 0;
            for (int64_t h = 0; h < hits; h++)
                sum += (int64_t)b.weight[h];
            add64(job->shared, &crowd[s], sum);
            if (job->over) { /* not listed: the later ends' share now */
                for (int64_t h = 0; h < hits; h++)
                    add64(job->shared, &crowd[b.at[h]], (int64_t)b.weight[h]);
                continue;
            }
            int32_t *restrict to = job->to + job->size;
            uint16_t *restrict lift = job->lift + job->size;
            for (int64_t h = 0; h < hits; h++) {
                to[h] = b.at[h];
                lift[h] = (uint16_t)(b.weight[h] - LIFT);
            }
            job->later[s] = (int32_t)hits;
            job->first[s] = job->size;
            job->size += hits;
        }
    }
    scratch_free(&b);
}

/* The piece's pairs into the backward rows of their later ends (the pieces in turn: the
 * rows fill in position order). */
static void fill_job(void *jobs, int k, int count)
{
    Job *job = (Job *)jobs + k;
    (void)count;
    const Grid *g = job->w->g;
    const int64_t *back = job->back;
    int64_t e = 0;
    for (int64_t s = g->cell_start[job->c0]; s < g->cell_start[job->c1]; s++)
        for (int64_t h = 0; h < job->later[s]; h++, e++) {
            int32_t t = job->to[e];
            int64_t q = back[t] + job->degree[t]++;
            job->bnbr[q] = (int32_t)s;
            job->blift[q] = job->lift[e];
        }
}

/* The neighbours of every position s, in two rows: forward, the later[s] pairs it found,
 * from first[s] in the lists of the piece that holds it (positions piece_start[k] ..
 * piece_start[k + 1] - 1 belong to piece k); backward, those that found it, in position
 * order, bnbr[back[s]] .. bnbr[back[s + 1] - 1]. Weights are lift + LIFT. Each pair is
 * stored twice, 6 bytes each time. */
typedef struct {
    const Greedy *w;     /* with by_grid: the rows are found again in the grid */
    const int32_t *cell; /* (a,) the cell of each position, with by_grid */
    int by_grid;
    int pieces;
    int64_t *piece_start; /* (pieces + 1,) */
    int32_t **fnbr;       /* (pieces,) */
    uint16_t **flift;     /* (pieces,) */
    int32_t *later;
    int64_t *first, *back;
    int32_t *bnbr;
    uint16_t *blift;
} Rows;

static void rows_free(Rows *r)
{
    for (int k = 0; r->fnbr && k < r->pieces; k++) {
        give(r->fnbr[k]);
        give(r->flift[k]);
    }
    free(r->piece_start);
    free(r->fnbr);
    free(r->flift);
    give(r->later);
    give(r->first);
    give(r->back);
    give(r->bnbr);
    give(r->blift);
    give((void *)r->cell);
}

/* Lists hold at most this many pairs a point (about 9 at 8 candidates to a kept point, 5 for
 * --radius): beyond it (clustered points in an uncapped grid can have millions of pairs) the
 * rows are found again in the grid when needed, slower but in memory that does not grow
 * with the pairs. */
#define MOST_LISTED 64

/* Rows found again in the grid: each position's cell. */
static int by_grid(const Greedy *w, Rows *rows)
{
    const Grid *g = w->g;
    int32_t *cell = take((g->a ? g->a : 1) * sizeof(int32_t));
    if (!cell)
        return 0;
    for (int64_t c = 0; c < g->cells; c++)
        for (int64_t s = g->cell_start[c]; s < g->cell_start[c + 1]; s++)
            cell[s] = (int32_t)c;
    rows->w = w;
    rows->cell = cell;
    return 1;
}

/* The pieces of the cells, about PIECE_POINTS positions each (the cells of a piece hold
 * about equal numbers of points): their jobs, with room for the usual number of pairs
 * (about 9 a point at 8 candidates to a kept point), so that the lists seldom grow. */
static Job *pieces_of(const Greedy *w, int pieces, int64_t *crowd, int32_t *degree, const Rows *rows, int64_t *start,
                      int64_t *listed)
{
    const Grid *g = w->g;
    int64_t a = g->a, c = 0;
    Job *jobs = calloc((size_t)pieces, sizeof *jobs);
    for (int k = 0; jobs && k < pieces; k++) {
        Job job = {w, c, g->cells, crowd, degree, rows->later, rows->first};
        while (k + 1 < pieces && job.c1 > c && g->cell_start[c] < a * (k + 1) / pieces)
            c++;
        job.c1 = k + 1 < pieces ? c : g->cells;
        start[k] = g->cell_start[job.c0];
        job.listed = listed;
        job.budget = MOST_LISTED * a + 65536;
        jobs[k] = job;
    }
    start[pieces] = a;
    return jobs;
}

/* The crowding of every position into crowd (a,), and the neighbours of every position into
 * rows: the pair search in pieces of PIECE_POINTS positions on ``threads`` threads, the
 * backward rows filled in turn (in position order, no atomics). */
static int crowding(const Greedy *w, int threads, int64_t *crowd, Rows *rows)
{
    const Grid *g = w->g;
    int64_t a = g->a, m = a ? a : 1;
    int pieces = (int)((a + PIECE_POINTS - 1) / PIECE_POINTS);
    pieces = pieces < 1 ? 1 : pieces;
    rows->w = w;
    rows->pieces = pieces;
    rows->later = take(m * sizeof(int32_t));
    rows->first = take(m * sizeof(int64_t));
    rows->back = take((m + 1) * sizeof(int64_t));
    rows->piece_start = malloc(sizeof(int64_t) * ((size_t)pieces + 1));
    rows->fnbr = calloc((size_t)pieces, sizeof *rows->fnbr);
    rows->flift = calloc((size_t)pieces, sizeof *rows->flift);
    int32_t *degree = take_zeroed(m * sizeof(int32_t));
    int ok = rows->later && rows->first && rows->back && rows->piece_start && rows->fnbr && rows->flift && degree;
    int64_t listed = 0;
    Job *jobs = ok ? pieces_of(w, pieces, crowd, degree, rows, rows->piece_start, &listed) : NULL;
    ok = ok && jobs;
    int shared = threads_for(pieces, threads) > 1;
    for (int k = 0; ok && k < pieces; k++)
        jobs[k].shared = shared;
    if (ok) {
        memset(crowd, 0, (size_t)m * sizeof *crowd);
        in_pieces(pieces, threads, crowd_job, jobs);
    }
    for (int k = 0; ok && k < pieces; k++)
        ok &= jobs[k].ok;
    rows->by_grid = listed > MOST_LISTED * a + 65536; /* (then some pieces stopped listing) */
    for (int k = 0; ok && k < pieces; k++) /* the listed pairs' later ends, in turn: no atomics */
        for (int64_t e = 0; e < jobs[k].size; e++) {
            crowd[jobs[k].to[e]] += (int64_t)jobs[k].lift[e] + LIFT;
            degree[jobs[k].to[e]]++;
        }
    if (ok) {
        rows->back[0] = 0;
        for (int64_t s = 0; s < a; s++) {
            rows->back[s + 1] = rows->back[s] + degree[s];
            degree[s] = 0;
        }
    }
    if (ok && rows->by_grid)
        ok = by_grid(w, rows);
    else if (ok) {
        rows->bnbr = take((rows->back[a] ? rows->back[a] : 1) * sizeof(int32_t));
        rows->blift = take((rows->back[a] ? rows->back[a] : 1) * sizeof(uint16_t));
        ok = rows->bnbr && rows->blift;
        for (int k = 0; ok && k < pieces; k++) {
            jobs[k].back = rows->back;
            jobs[k].bnbr = rows->bnbr;
            jobs[k].blift = rows->blift;
        }
        for (int k = 0; ok && k < pieces; k++)
            fill_job(jobs, k, pieces);
    }
    for (int k = 0; jobs && k < pieces; k++) {
        rows->fnbr[k] = rows->by_grid ? NULL : jobs[k].to;
        rows->flift[k] = rows->by_grid ? NULL : jobs[k].lift;
        if (rows->by_grid)
            give(jobs[k].to), give(jobs[k].lift);
    }
    free(jobs);
    give(degree);
    return ok;
}

/* The least x with sqrt(x) >= radius. sqrt is monotonic, so sqrt(x) < radius exactly when
 * x is below it: the test needs no square root. */
static double square_bound(double radius)
{
    double x = radius * radius;
    while (x > 0 && sqrt(x) >= radius)
        x = nextafter(x, 0);
    while (sqrt(x) < radius)
        x = nextafter(x, INFINITY);
    return x;
}

/* The k-th smallest (from 0) of v (n,) >= 0, which it overwrites: eleven bits at a time
 * from the top, counting, then keeping only the values in the bucket of the k-th. */
static int64_t kth_smallest(int64_t *v, int64_t n, int64_t k)
{
    uint64_t top = 1;
    for (int64_t i = 0; i < n; i++)
        top |= (uint64_t)v[i];
    int shift = 64 - __builtin_clzll(top);
    for (;;) {
        shift = shift > 11 ? shift - 11 : 0;
        int64_t count[2048] = {0};
        for (int64_t i = 0; i < n; i++)
            count[(v[i] >> shift) & 2047]++;
        int64_t b = 0;
        while (k >= count[b])
            k -= count[b++];
        int64_t m = 0;
        for (int64_t i = 0; i < n; i++) {
            v[m] = v[i];
            m += ((v[i] >> shift) & 2047) == b;
        }
        if (shift == 0)
            return v[0];
        n = m;
    }
}

/* What gone[] says of a position: undecided (0), kept, or dropped. */
#define KEPT 1
#define DROPPED 2

/* The batch of a round: the max(least, ceil(u / share)) least crowded of the u undecided
 * positions left (u,), ties included, into batch, by ascending crowding, ties by active
 * number (order). value and key are room for u entries. Returns how many, or -1 when out of
 * memory. */
static int64_t batch_of(const int64_t *crowd, const int32_t *left, int64_t u, int64_t share, int64_t least,
                        const int64_t *order, int64_t *value, int32_t *batch, uint64_t *key)
{
    int64_t want = u / share + (u % share != 0), n = 0;
    want = want > least ? want : least;
    int64_t limit = INT64_MAX;
    if (want < u) {
        for (int64_t t = 0; t < u; t++)
            value[t] = crowd[left[t]];
        limit = kth_smallest(value, u, want - 1);
    }
    for (int64_t t = 0; t < u; t++) {
        batch[n] = left[t];
        key[n] = (uint64_t)order[left[t]];
        n += crowd[left[t]] <= limit;
    }
    /* stable sorts: by active number, then by crowding */
    if (!radix_sort(key, batch, n))
        return -1;
    for (int64_t t = 0; t < n; t++)
        key[t] = (uint64_t)crowd[batch[t]];
    return radix_sort(key, batch, n) ? n : -1;
}


/* A run of neighbours and their weights less LIFT. */
typedef struct {
    const int32_t *nbr;
    const uint16_t *lift;
    int64_t n;
} Span;

/* The two rows of position s; b is room for them when they are found in the grid (then
 * the first holds s itself too, with weight 65536: its own crowding no longer matters). */
static inline void rows_of(const Rows *r, int32_t s, Span row[2], Scratch *b)
{
    if (r->by_grid) {
        const int32_t *around = r->w->ranges + 18 * r->cell[s];
        int64_t n = 0;
        for (int col = 0; col < 9; col++)
            n = find_hits(r->w->g, s, around[2 * col], around[2 * col + 1], r->w->r2, b->d2, b->at, n, b->tmp);
        weigh(b->d2, b->weight, n, 1.0 / (2.0 * r->w->radius));
        for (int64_t h = 0; h < n; h++)
            b->lift[h] = (uint16_t)(b->weight[h] - LIFT);
        row[0] = (Span){b->at, b->lift, n};
        row[1] = (Span){NULL, NULL, 0};
        return;
    }
    /* the piece of s, piece_start[k] <= s < piece_start[k + 1], from where s lies in the
     * positions (the pieces hold about equal numbers of them) */
    int64_t a = r->w->g->a;
    int k = (int)((int64_t)s * r->pieces / (a ? a : 1));
    k = k < r->pieces ? k : r->pieces - 1;
    while (k > 0 && r->piece_start[k] > s)
        k--;
    while (r->piece_start[k + 1] <= s)
        k++;
    row[0] = (Span){r->fnbr[k] + r->first[s], r->flift[k] + r->first[s], r->later[s]};
    row[1] = (Span){r->bnbr + r->back[s], r->blift + r->back[s], r->back[s + 1] - r->back[s]};
}

/* Ask early for the rows of position s: far apart in memory when visited in crowding
 * order. */
static inline void prefetch_rows(const Rows *r, int32_t s)
{
    Span row[2];
    if (r->by_grid)
        return;
    rows_of(r, s, row, NULL);
    for (int h = 0; h < 2; h++) {
        __builtin_prefetch(row[h].nbr);
        __builtin_prefetch(row[h].lift);
    }
}

/* The greedy over a round's batch (n,): a point not gone yet is kept, and its neighbours go. */
static void keep_batch(const Rows *r, const int32_t *batch, int64_t n, const int64_t *order, char *gone,
                       npy_bool *kept, Scratch *b)
{
    for (int64_t k = 0; k < n; k++) {
        int32_t p = batch[k];
        if (k + 8 < n)
            prefetch_rows(r, batch[k + 8]);
        if (gone[p])
            continue;
        kept[order[p]] = 1;
        gone[p] = KEPT;
        Span row[2];
        rows_of(r, p, row, b);
        for (int h = 0; h < 2; h++)
            for (int64_t e = 0; e < row[h].n; e++)
                gone[row[h].nbr[e]] = gone[row[h].nbr[e]] ? gone[row[h].nbr[e]] : DROPPED;
    }
}

/* The points just dropped leave their neighbours' crowding (that of points gone no longer
 * matters); left (u,) keeps the undecided, in order, and the new count is returned. The
 * dropped are listed in room (u,) in position order, so that their rows are read in
 * memory order. */
static int64_t drop(const Rows *r, int32_t *left, int64_t u, char *gone, int64_t *restrict crowd, int32_t *room,
                    Scratch *b)
{
    int64_t still = 0, dropped = 0;
    for (int64_t t = 0; t < u; t++) {
        int32_t s = left[t];
        room[dropped] = s;
        dropped += gone[s] == DROPPED;
        left[still] = s;
        still += !gone[s];
    }
    for (int64_t k = 0; k < dropped; k++) {
        if (k + 8 < dropped)
            prefetch_rows(r, room[k + 8]);
        Span row[2];
        rows_of(r, room[k], row, b);
        for (int h = 0; h < 2; h++)
            for (int64_t e = 0; e < row[h].n; e++)
                crowd[row[h].nbr[e]] -= row[h].lift[e] + LIFT;
    }
    return still;
}

PyDoc_STRVAR(greedy_doc,
"greedy(order, xyz, ukey, cell_start, reach, radius, kept, share, least, threads)\n\n"
"greedy.least_crowded_first on the pairs of pairs.self_pairs(..., reach) shorter\n"
"than radius: a maximal independent set taken in rounds. Each round takes the max(least,\n"
"ceil(u / share)) least crowded of the u undecided points (ties included), crowding being\n"
"the sum of floor((1 - d * (1 / (2 radius))) * 65536) over undecided neighbours, and keeps\n"
"them greedily in ascending crowding, ties by active number. Fills kept (a,) bool, by\n"
"active number. The first crowding is summed on ``threads`` threads; the result does not\n"
"depend on how many.");


static PyObject *greedy(PyObject *self, PyObject *args)
{
    Grid g;
    double reach, radius;
    PyObject *okept;
    Py_ssize_t share, least;
    int threads;
    if (!get_grid(args, &g, &reach, &radius, &okept, &share, &least, &threads))
        return NULL;
    if (share < 1 || least < 1)
        return PyErr_Format(PyExc_ValueError, "share and least must be positive");
    npy_bool *kept = PyArray_DATA((PyArrayObject *)okept);
    int64_t a = g.a, m = a ? a : 1;
    int32_t *ranges = take((18 * g.cells + 1) * sizeof(int32_t));
    int64_t *crowd = take(m * sizeof(int64_t)), *value = take(m * sizeof(int64_t));
    int32_t *left = take(m * sizeof(int32_t)), *batch = take(m * sizeof(int32_t));
    uint64_t *key = take(m * sizeof(uint64_t));
    char *gone = take_zeroed(m);
    Rows rows = {0};
    Scratch near = {0};
    int ok = ranges && crowd && value && left && batch && key && gone;
    Py_BEGIN_ALLOW_THREADS
    double below = square_bound(radius); /* d < radius */
    Greedy w = {&g, ranges, 0, reach * reach < below ? reach * reach : below, radius};
    if (ok) {
        column_ranges(&g, ranges);
        w.most = most_around(&g, ranges);
        ok = crowding(&w, threads, crowd, &rows) && (!rows.by_grid || scratch_init(&near, w.most));
    }
    if (ok)
        memset(kept, 0, (size_t)a);
    /* left: the undecided positions, ascending */
    for (int64_t s = 0; ok && s < a; s++)
        left[s] = (int32_t)s;
    for (int64_t u = ok ? a : 0; ok && u > 0;) {
        int64_t n = batch_of(crowd, left, u, share, least, g.order, value, batch, key);
        ok = n >= 0;
        if (ok) {
            keep_batch(&rows, batch, n, g.order, gone, kept, &near);
            u = drop(&rows, left, u, gone, crowd, batch, &near);
        }
    }
    Py_END_ALLOW_THREADS
    rows_free(&rows);
    scratch_free(&near);
    give(ranges);
    give(crowd);
    give(value);
    give(left);
    give(batch);
    give(key);
    give(gone);
    if (!ok)
        return PyErr_NoMemory();
    Py_RETURN_NONE;
}

PyDoc_STRVAR(use_avx512_doc,
"use_avx512(wanted) -> bool\n\n"
"Whether the distance loops use AVX-512 from now on: wanted and the CPU has it (the\n"
"same hits either way). native.kernel() passes SCATTER_NO_AVX512's choice.");

static PyObject *use_avx512(PyObject *self, PyObject *args)
{
    int wanted;
    if (!PyArg_ParseTuple(args, "p", &wanted))
        return NULL;
    find_hits = hits_in;
#if defined(__x86_64__) && defined(__GNUC__)
    if (wanted && __builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl"))
        find_hits = hits_in_avx512;
#endif
    return PyBool_FromLong(find_hits != hits_in);
}

static PyMethodDef methods[] = {
    {"use_avx512", use_avx512, METH_VARARGS, use_avx512_doc},
    {"grid", grid, METH_VARARGS, grid_doc},
    {"pairs", pairs, METH_VARARGS, pairs_doc},
    {"greedy", greedy, METH_VARARGS, greedy_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cthinning",
    "Compiled grid, pair search and greedy thinning, with the same results as the NumPy path (pairs.py, greedy.py).", -1,
    methods,
};

PyMODINIT_FUNC PyInit__cthinning(void)
{
    import_array();
#if defined(__x86_64__) && defined(__GNUC__)
    __builtin_cpu_init();
    if (__builtin_cpu_supports("avx512f") && __builtin_cpu_supports("avx512vl"))
        find_hits = hits_in_avx512;
#endif
    PyObject *m = PyModule_Create(&module);
    if (m && (PyModule_AddIntConstant(m, "BITS", BITS) < 0 || PyModule_AddIntConstant(m, "MAX_CELLS", MAX_CELLS) < 0 ||
              PyModule_AddObject(m, "CROWD_SCALE", PyFloat_FromDouble(CROWD_SCALE)) < 0))
        Py_CLEAR(m);
    return m;
}
