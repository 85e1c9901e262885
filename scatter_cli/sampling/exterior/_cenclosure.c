/* Compiled enclosure certificate: the same faces as enclosure.py's NumPy path.
 *
 * parts(): the closed parts of a geometry (edge multiplicities by a counting sort on
 * the smaller vertex, connected parts by union-find with the smallest vertex as root,
 * numbered in the order of their smallest vertex, as np.unique numbers them).
 * enclosed(): enclosure.enclosed_faces, step by step: the faces in part order, their
 * boxes, the shells (the largest boxes first), the grid, each shell's cells and its
 * crossings with the lines along x, the parity of every cell, and the faces whose grown
 * box touches only cells of odd parity for a shell that does not touch them. Every
 * float64 operation is the NumPy code's, in its order (built with -ffp-contract=off),
 * and float-to-int conversions give what NumPy's give on x86-64 (the minimum int64 when
 * out of range), so the two paths certify the same faces. The GIL is released while
 * they run. Indices are checked: an index out of range raises ValueError.
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



/* get_rows() for an (n, 3) array */
static int get3(PyObject *obj, int type, PyArrayObject **out, const char *name)
{
    npy_intp rows;
    return get_rows(obj, type, 3, out, &rows, name);
}

/* (int64)x as NumPy's astype gives it on x86-64: the minimum int64 when x is NaN or out of range. */
static inline int64_t to_i64(double x)
{
    if (!(x >= -9223372036854775808.0 && x < 9223372036854775808.0))
        return INT64_MIN;
    return (int64_t)x;
}

/* to_i64(floor(x)) and to_i64(ceil(x)), by truncation (the same values for every x:
 * x is in range exactly when its floor and its ceiling are; without SSE4.1, floor and
 * ceil cost several times more) */
static inline int64_t floor_i64(double x)
{
    if (!(x >= -9223372036854775808.0 && x < 9223372036854775808.0))
        return INT64_MIN;
    int64_t t = (int64_t)x;
    return t - ((double)t > x);
}

static inline int64_t ceil_i64(double x)
{
    if (!(x >= -9223372036854775808.0 && x < 9223372036854775808.0))
        return INT64_MIN;
    int64_t t = (int64_t)x;
    return t + ((double)t < x);
}

static inline int64_t clip(int64_t v, int64_t lo, int64_t hi) { return v < lo ? lo : v > hi ? hi : v; }

/* below this many faces a shell is done on one thread */
#define THREAD_FACES 65536
/* faces (or vertices, lines) a share at least, when a step is cut into many a thread */
#define SHARE_FACES 4096

/* ---- parts ---- */

static int64_t find(int64_t *root, int64_t x)
{
    while (root[x] != x) {
        root[x] = root[root[x]];
        x = root[x];
    }
    return x;
}

static void unite(int64_t *root, int64_t a, int64_t b)
{
    a = find(root, a);
    b = find(root, b);
    if (a < b)
        root[b] = a;
    else if (b < a)
        root[a] = b;
}

/* What parts() shares between its threads. First the unions (then the roots and their
 * numbers) on one, the edges counted by their smaller vertex on the other, for each half
 * of the faces; then each half's edges into the buckets on a thread each; then, split by
 * vertices and faces, each vertex's odd edges and each face's part. */
typedef struct {
    const int64_t *ids, *f; /* ids NULL: each vertex its own id */
    int64_t nf, size, count;
    int64_t *root, *rank, *part;
    int64_t *cursor[2]; /* (size,) each: the edges of a half of the faces counted, then where they go */
    uint32_t *other;
    uint8_t *odd;
} Parts;

static inline int64_t vid(const Parts *w, int64_t i) { return w->ids ? w->ids[w->f[i]] : w->f[i]; }

static void union_job(Parts *w)
{
    for (int64_t i = 0; i < w->size; i++)
        w->root[i] = i;
    for (int64_t i = 0; i < w->nf; i++) { /* two edges join a face's corners */
        int64_t a = vid(w, 3 * i), b = vid(w, 3 * i + 1), c = vid(w, 3 * i + 2);
        unite(w->root, a, b);
        unite(w->root, b, c);
    }
    /* a root is the smallest vertex of its part, so one pass in order flattens them */
    int64_t count = 0;
    for (int64_t i = 0; i < w->size; i++) {
        w->root[i] = w->root[w->root[i]];
        if (w->root[i] == i)
            w->rank[i] = count++;
    }
    w->count = count;
}

/* the edge-uses of half h of the faces: i0 .. i1 - 1 */
static inline void half(const Parts *w, int h, int64_t *i0, int64_t *i1)
{
    *i0 = h ? 3 * (w->nf / 2) : 0, *i1 = h ? 3 * w->nf : 3 * (w->nf / 2);
}

static void count_job(Parts *w)
{
    for (int h = 0; h < 2; h++) {
        int64_t i0, i1, *count = w->cursor[h];
        half(w, h, &i0, &i1);
        for (int64_t i = i0; i < i1; i++) {
            int64_t a = vid(w, i), b = vid(w, i % 3 == 2 ? i - 2 : i + 1);
            count[a < b ? a : b]++;
        }
    }
}

static void parts_first(void *arg, int k, int count)
{
    (void)count;
    if (k == 0)
        union_job(arg);
    else
        count_job(arg);
}

/* the buckets: vertex a's from the end of a - 1's (the first half's edges first) */
static void bucket_starts(Parts *w)
{
    int64_t at = 0;
    for (int64_t a = 0; a < w->size; a++) {
        int64_t n0 = w->cursor[0][a], n1 = w->cursor[1][a];
        w->cursor[0][a] = at, w->cursor[1][a] = at + n0;
        at += n0 + n1;
    }
}

static void fill_half(void *arg, int h, int count)
{
    (void)count;
    Parts *w = arg;
    int64_t i0, i1, *cursor = w->cursor[h];
    half(w, h, &i0, &i1);
    for (int64_t i = i0; i < i1; i++) {
        int64_t a = vid(w, i), b = vid(w, i % 3 == 2 ? i - 2 : i + 1);
        w->other[cursor[a < b ? a : b]++] = (uint32_t)(a < b ? b : a);
    }
}

static int cmp_u32(const void *p, const void *q)
{
    uint32_t a = *(const uint32_t *)p, b = *(const uint32_t *)q;
    return (a > b) - (a < b);
}

static void sort_small(uint32_t *x, int64_t n)
{
    if (n > 32) {
        qsort(x, (size_t)n, sizeof *x, cmp_u32);
        return;
    }
    for (int64_t i = 1; i < n; i++) {
        uint32_t v = x[i];
        int64_t j = i;
        while (j > 0 && x[j - 1] > v) {
            x[j] = x[j - 1];
            j--;
        }
        x[j] = v;
    }
}

/* odd[a]: an edge (a, b > a) is used an odd number of times; each face's part */
static void parts_second(void *arg, int k, int count)
{
    Parts *w = arg;
    int64_t a0, a1, i0, i1;
    share(w->size, k, count, &a0, &a1);
    for (int64_t a = a0; a < a1; a++) { /* (the second half's cursors now end the buckets) */
        int64_t begin = a ? w->cursor[1][a - 1] : 0, n = w->cursor[1][a] - begin;
        uint32_t *b = w->other + begin;
        sort_small(b, n);
        uint8_t odd = 0;
        for (int64_t j = 0; j < n;) {
            int64_t run = j;
            while (run < n && b[run] == b[j])
                run++;
            odd |= (run - j) % 2;
            j = run;
        }
        w->odd[a] = odd;
    }
    share(w->nf, k, count, &i0, &i1);
    for (int64_t i = i0; i < i1; i++)
        w->part[i] = w->rank[w->root[vid(w, 3 * i)]];
}

PyDoc_STRVAR(parts_doc, "parts(ids (V,) i8, or V (each vertex its own id), faces (F,3) i8, threads) -> "
                        "(part (F,) i8, closed (P,) bool): enclosure._parts.");

static PyObject *parts(PyObject *self, PyObject *args)
{
    PyObject *oids, *ofaces;
    PyArrayObject *ids_a = NULL, *fa;
    int threads;
    long long count = -1;
    if (!PyArg_ParseTuple(args, "OOi", &oids, &ofaces, &threads) || !get3(ofaces, NPY_INT64, &fa, "faces"))
        return NULL;
    if (PyLong_Check(oids)) {
        if ((count = PyLong_AsLongLong(oids)) < 0 && !PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "parts: negative vertex count");
        if (PyErr_Occurred())
            return NULL;
    } else if (!get(oids, NPY_INT64, -1, &ids_a, "ids"))
        return NULL;
    npy_intp nf = PyArray_SIZE(fa) / 3;
    if (nf == 0) {
        PyErr_SetString(PyExc_ValueError, "parts: no faces");
        return NULL;
    }
    const int64_t *ids = ids_a ? PyArray_DATA(ids_a) : NULL, *f = PyArray_DATA(fa);
    int64_t size = 0;
    if (ids) {
        npy_intp nv = PyArray_SIZE(ids_a);
        for (npy_intp i = 0; i < 3 * nf; i++)
            if (f[i] < 0 || f[i] >= nv || ids[f[i]] < 0 || ids[f[i]] >= nv) {
                PyErr_SetString(PyExc_ValueError, "parts: index out of range");
                return NULL;
            }
        for (npy_intp i = 0; i < nv; i++)
            size = ids[i] + 1 > size ? ids[i] + 1 : size;
        if (size > nv || size < 1) {
            PyErr_SetString(PyExc_ValueError, "parts: ids out of range");
            return NULL;
        }
    } else {
        for (npy_intp i = 0; i < 3 * nf; i++)
            if (f[i] < 0 || f[i] >= count) {
                PyErr_SetString(PyExc_ValueError, "parts: index out of range");
                return NULL;
            }
        size = count;
    }
    if (size > (int64_t)UINT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "parts: more than 2**32 - 1 vertices");
        return NULL;
    }
    Parts w = {ids, f, nf, size, 0, malloc(sizeof(int64_t) * (size_t)size), malloc(sizeof(int64_t) * (size_t)size),
               NULL, {calloc((size_t)size, sizeof(int64_t)), calloc((size_t)size, sizeof(int64_t))},
               malloc(sizeof(uint32_t) * 3 * (size_t)nf), malloc((size_t)size)};
    uint8_t *closed = NULL;
    PyArrayObject *part_a = (PyArrayObject *)PyArray_SimpleNew(1, (npy_intp[]){nf}, NPY_INT64);
    if (!w.root || !w.rank || !w.cursor[0] || !w.cursor[1] || !w.other || !w.odd || !part_a) {
        free(w.root), free(w.rank), free(w.cursor[0]), free(w.cursor[1]), free(w.other), free(w.odd);
        Py_XDECREF(part_a);
        return PyErr_NoMemory();
    }
    w.part = PyArray_DATA(part_a);
    int jobs = nf < THREAD_FACES ? 1 : threads < 1 ? 1 : threads;
    Py_BEGIN_ALLOW_THREADS
    in_parallel(jobs > 1 ? 2 : 1, parts_first, &w);
    if (jobs == 1)
        count_job(&w);
    bucket_starts(&w);
    in_parallel(jobs > 1 ? 2 : 1, fill_half, &w);
    if (jobs == 1)
        fill_half(&w, 1, 1);
    in_pieces(pieces_for(nf > size ? nf : size, SHARE_FACES, jobs), jobs, parts_second, &w);
    if ((closed = malloc((size_t)w.count ? (size_t)w.count : 1))) {
        memset(closed, 1, (size_t)w.count);
        for (int64_t a = 0; a < size; a++)
            if (w.odd[a])
                closed[w.rank[w.root[a]]] = 0;
    }
    Py_END_ALLOW_THREADS
    free(w.root), free(w.rank), free(w.cursor[0]), free(w.cursor[1]), free(w.other), free(w.odd);
    PyArrayObject *closed_a = closed ? (PyArrayObject *)PyArray_SimpleNew(1, (npy_intp[]){w.count}, NPY_BOOL) : NULL;
    if (!closed_a) {
        free(closed);
        Py_DECREF(part_a);
        return closed ? NULL : PyErr_NoMemory();
    }
    memcpy(PyArray_DATA(closed_a), closed, (size_t)w.count);
    free(closed);
    return Py_BuildValue("NN", part_a, closed_a);
}

/* ---- enclosed ---- */

typedef struct {
    double origin[3], step, grow;
    int64_t shape[3];
} Grid;

/* enclosure.Grid.ranges for one box lo..hi grown by grow: first and last cells, clipped */
static void ranges(const Grid *g, const double *lo, const double *hi, double grow, int64_t *first, int64_t *last)
{
    for (int k = 0; k < 3; k++) {
        first[k] = clip(floor_i64((lo[k] - grow - g->origin[k]) / g->step), 0, g->shape[k] - 1);
        last[k] = clip(floor_i64((hi[k] + grow - g->origin[k]) / g->step), 0, g->shape[k] - 1);
    }
}

typedef struct {
    double key;
    uint64_t bit;
} Crossing;

typedef struct {
    Crossing *at;
    size_t n, room;
} Crossings;

/* One bit a shell for each cell: where the shell's faces may touch. Cells are 1, 2, 4
 * or 8 bytes wide, as few as the shells need (fresh memory is dear here). */
typedef struct {
    void *at;
    int width;
} Cover;

static inline uint64_t cover_get(Cover c, int64_t i)
{
    switch (c.width) {
    case 1:
        return ((const uint8_t *)c.at)[i];
    case 2:
        return ((const uint16_t *)c.at)[i];
    case 4:
        return ((const uint32_t *)c.at)[i];
    default:
        return ((const uint64_t *)c.at)[i];
    }
}

/* OR ``bit`` into cells i .. i + n - 1 where touch (n,) is set */
static void cover_or(Cover c, int64_t i, const uint8_t *touch, int64_t n, uint64_t bit)
{
#define COVER_OR(type)                                                                                                 \
    for (int64_t z = 0; z < n; z++)                                                                                    \
        ((type *)c.at)[i + z] |= (type)(bit & (0 - (uint64_t)(touch[z] != 0)));
    switch (c.width) {
    case 1:
        COVER_OR(uint8_t) break;
    case 2:
        COVER_OR(uint16_t) break;
    case 4:
        COVER_OR(uint32_t) break;
    default:
        COVER_OR(uint64_t) break;
    }
#undef COVER_OR
}

static int push(Crossings *c, double key, uint64_t bit)
{
    if (c->n == c->room) {
        size_t room = c->room ? 2 * c->room : 4096;
        Crossing *at = realloc(c->at, room * sizeof *at);
        if (!at)
            return 0;
        c->at = at, c->room = room;
    }
    c->at[c->n].key = key;
    c->at[c->n++].bit = bit;
    return 1;
}

static int cmp_key(const void *p, const void *q)
{
    double a = ((const Crossing *)p)->key, b = ((const Crossing *)q)->key;
    return (a > b) - (a < b);
}

typedef struct {
    const double *v;
    const int64_t *f;
    const int64_t *sorted; /* the faces in part order (NULL: they are) */
    const double *probe;
    const Grid *g;
} Scene;

/* the index of the s-th face in part order */
static inline int64_t face_at(const Scene *sc, int64_t s) { return sc->sorted ? sc->sorted[s] : s; }

/* the corners c[3][3] and box lo..hi of the s-th face in part order (boxes are not
 * stored: on this host fresh memory costs more than finding them again) */
static inline void corners(const Scene *sc, int64_t s, double c[3][3], double lo[3], double hi[3])
{
    const int64_t *f = sc->f + 3 * face_at(sc, s);
    for (int k = 0; k < 3; k++)
        for (int a = 0; a < 3; a++)
            c[k][a] = sc->v[3 * f[k] + a];
    for (int a = 0; a < 3; a++) {
        double l = c[0][a], h = c[0][a];
        l = c[1][a] < l ? c[1][a] : l, h = c[1][a] > h ? c[1][a] : h;
        l = c[2][a] < l ? c[2][a] : l, h = c[2][a] > h ? c[2][a] : h;
        lo[a] = l, hi[a] = h;
    }
}

/* corners c[3][3] in grid units, (c - origin) / step: q[3][3], and their box qlo..qhi.
 * Rounding is monotonic, so this box is the face's box in grid units, the values
 * enclosure.py computes from the face's box. */
static inline void scaled(const Grid *g, double c[3][3], double q[3][3], double qlo[3], double qhi[3])
{
    for (int k = 0; k < 3; k++)
        for (int a = 0; a < 3; a++)
            q[k][a] = (c[k][a] - g->origin[a]) / g->step;
    for (int a = 0; a < 3; a++) {
        double l = q[0][a], h = q[0][a];
        l = q[1][a] < l ? q[1][a] : l, h = q[1][a] > h ? q[1][a] : h;
        l = q[2][a] < l ? q[2][a] : l, h = q[2][a] > h ? q[2][a] : h;
        qlo[a] = l, qhi[a] = h;
    }
}

static inline double orient(const double *p, const double *q, double y, double z)
{
    return (q[1] - p[1]) * (z - p[2]) - (q[2] - p[2]) * (y - p[1]);
}

/* enclosure.crossings for one face (corners c, box qlo..qhi in grid units: scaled()): push its crossings' keys
 * (line + x / step / width) with ``bit``, flag unsure lines; 0 when out of memory */
static int cross_face(const Scene *sc, double c[3][3], const double qlo[3], const double qhi[3], uint64_t bit,
                      Crossings *out, uint8_t *unsure)
{
    const Grid *g = sc->g;
    const double s = g->step, *o = g->origin, *P = sc->probe, width = (double)g->shape[0] + 2.0;
    const int64_t nz = g->shape[2];
    /* (the shell lies inside the grid: the clamps change nothing but keep every line in it;
     * most faces meet no line, and ceil(x) <= j, for an integer j, is x <= j) */
    int64_t j1 = floor_i64(qhi[1] - P[1]);
    j1 = j1 >= g->shape[1] ? g->shape[1] - 1 : j1;
    if (j1 < 0 || (double)j1 < qlo[1] - P[1])
        return 1;
    int64_t k1 = floor_i64(qhi[2] - P[2]);
    k1 = k1 >= nz ? nz - 1 : k1;
    if (k1 < 0 || (double)k1 < qlo[2] - P[2])
        return 1;
    int64_t j0 = ceil_i64(qlo[1] - P[1]), k0 = ceil_i64(qlo[2] - P[2]);
    j0 = j0 < 0 ? 0 : j0, k0 = k0 < 0 ? 0 : k0;
    double near[3][3];
    for (int v = 0; v < 3; v++)
        for (int k = 0; k < 3; k++)
            near[v][k] = c[v][k] - o[k];
    double edge = 0.0;
    for (int v = 0; v < 3; v++)
        for (int k = 1; k < 3; k++) {
            double e = fabs(near[v][k] - near[(v + 1) % 3][k]);
            edge = e > edge ? e : edge;
        }
    double tol = (edge > 1e-300 ? edge : 1e-300) * s * 1e-9;
    for (int64_t j = j0; j <= j1; j++)
        for (int64_t k = k0; k <= k1; k++) {
            double y = ((double)j + P[1]) * s, z = ((double)k + P[2]) * s;
            double d0 = orient(near[1], near[2], y, z), d1 = orient(near[2], near[0], y, z),
                   d2 = orient(near[0], near[1], y, z);
            int inside = (d0 > tol && d1 > tol && d2 > tol) || (d0 < -tol && d1 < -tol && d2 < -tol);
            int touch = !inside && ((d0 >= -tol && d1 >= -tol && d2 >= -tol) || (d0 <= tol && d1 <= tol && d2 <= tol));
            int64_t line = j * nz + k;
            if (touch)
                unsure[line] = 1;
            if (inside) {
                double x = (d0 * near[0][0] + d1 * near[1][0] + d2 * near[2][0]) / (d0 + d1 + d2);
                if (!push(out, (double)line + x / s / width, bit))
                    return 0;
            }
        }
    return 1;
}



/* What one thread gathers of a shell's faces s0..s1-1, in its box of cells base + (n):
 * the cells of the corners of faces no wider than a cell less grow (``point``), the boxes
 * of the others (``diff``, a difference array, made at the first), the crossings and the
 * unsure lines (enclosure.shell_cover and enclosure.crossings), from the pieces of the
 * faces it takes: ORs, sums of whole numbers and crossings sorted later, so which thread
 * takes which piece changes nothing. */
typedef struct {
    const Scene *sc;
    int64_t s0, s1, base[3], n[3];
    uint64_t bit;
    uint8_t *point, *unsure;
    int32_t *diff;
    Crossings *cross;
    int ok;
} Share;

/* piece k of pieces of the faces, into the share of the thread that takes it */
static void mark_share(void *shares, int thread, int k, int pieces)
{
    /* on copies: the threads' Share and Crossings lie side by side, and writing them at
     * every face would make the threads fight over their cache lines */
    Share *w = (Share *)shares + thread, me = *w;
    Crossings cross = *me.cross;
    const Grid *g = me.sc->g;
    const int64_t *n = me.n, *base = me.base, e1 = n[1] + 1, e2 = n[2] + 1;
    int64_t t0, t1;
    share(me.s1 - me.s0, k, pieces, &t0, &t1);
    int ok = me.ok;
    for (int64_t t = me.s0 + t0; t < me.s0 + t1 && ok; t++) {
        double c[3][3], lo[3], hi[3], qc[3][3], qlo[3], qhi[3];
        corners(me.sc, t, c, lo, hi);
        scaled(g, c, qc, qlo, qhi);
        double span = hi[0] - lo[0];
        span = hi[1] - lo[1] > span ? hi[1] - lo[1] : span;
        span = hi[2] - lo[2] > span ? hi[2] - lo[2] : span;
        if (span <= g->step - g->grow) {
            for (int v = 0; v < 3; v++) {
                int64_t at[3];
                for (int k = 0; k < 3; k++)
                    at[k] = clip(floor_i64(qc[v][k]) - base[k], 0, n[k] - 1);
                me.point[(at[0] * n[1] + at[1]) * n[2] + at[2]] = 1;
            }
        } else {
            if (!me.diff && !(me.diff = calloc((size_t)((n[0] + 1) * e1 * e2), sizeof(int32_t)))) {
                ok = 0;
                break;
            }
            int64_t a[3], b[3];
            ranges(g, lo, hi, g->grow, a, b);
            for (int k = 0; k < 3; k++) {
                a[k] = clip(a[k] - base[k], 0, n[k] - 1);
                b[k] = clip(b[k] - base[k], 0, n[k] - 1) + 1;
            }
            for (int corner = 0; corner < 8; corner++) {
                int64_t x = corner & 1 ? b[0] : a[0], y = corner & 2 ? b[1] : a[1], z = corner & 4 ? b[2] : a[2];
                int picked = (corner & 1) + ((corner >> 1) & 1) + ((corner >> 2) & 1);
                me.diff[(x * e1 + y) * e2 + z] += picked % 2 ? -1 : 1;
            }
        }
        ok = cross_face(me.sc, c, qlo, qhi, me.bit, &cross, me.unsure);
    }
    w->diff = me.diff, w->ok = ok;
    *w->cross = cross;
}

/* prefix sums of a difference array d (e0, e1, e2) along each axis */
static void summed(int32_t *d, int64_t e0, int64_t e1, int64_t e2)
{
    for (int64_t x = 0; x < e0; x++)
        for (int64_t y = 0; y < e1; y++)
            for (int64_t z = 1; z < e2; z++)
                d[(x * e1 + y) * e2 + z] += d[(x * e1 + y) * e2 + z - 1];
    for (int64_t x = 0; x < e0; x++)
        for (int64_t y = 1; y < e1; y++)
            for (int64_t z = 0; z < e2; z++)
                d[(x * e1 + y) * e2 + z] += d[(x * e1 + y - 1) * e2 + z];
    for (int64_t x = 1; x < e0; x++)
        for (int64_t y = 0; y < e1; y++)
            for (int64_t z = 0; z < e2; z++)
                d[(x * e1 + y) * e2 + z] += d[((x - 1) * e1 + y) * e2 + z];
}

/* o (len) = m (len) OR, where they exist, the len bytes before m and after it */
static void or_neighbours(uint8_t *o, const uint8_t *m, int64_t len, int before, int after)
{
    memcpy(o, m, (size_t)len);
    if (before)
        for (int64_t c = 0; c < len; c++)
            o[c] |= m[c - len];
    if (after)
        for (int64_t c = 0; c < len; c++)
            o[c] |= m[c + len];
}

/* mask (n) grown by one cell along each axis in turn (within n): the cells and their 26
 * neighbours; ``spare`` of the same size. Returns the grown mask (mask or spare). */
static uint8_t *grow_cells(uint8_t *mask, uint8_t *spare, const int64_t *n)
{
    const int64_t row = n[2], slab = n[1] * n[2], rows = n[0] * n[1];
    for (int64_t r = 0; r < rows; r++) { /* along z */
        const uint8_t *m = mask + r * row;
        uint8_t *o = spare + r * row;
        memcpy(o, m, (size_t)row);
        for (int64_t z = 1; z < row; z++)
            o[z] |= m[z - 1];
        for (int64_t z = 0; z + 1 < row; z++)
            o[z] |= m[z + 1];
    }
    for (int64_t x = 0; x < n[0]; x++) /* along y: rows */
        for (int64_t y = 0; y < n[1]; y++)
            or_neighbours(mask + x * slab + y * row, spare + x * slab + y * row, row, y > 0, y + 1 < n[1]);
    for (int64_t x = 0; x < n[0]; x++) /* along x: slabs */
        or_neighbours(spare + x * slab, mask + x * slab, slab, x > 0, x + 1 < n[0]);
    return spare;
}

/* One shell, faces s0..s1-1 of box slo..shi, on up to ``threads`` threads: OR ``bit``
 * into ``cover`` where its faces may touch, push its crossings, flag unsure lines
 * (the order the threads find them in changes nothing: crossings are sorted by key,
 * and equal keys all fall on one side of a probe). 0 when out of memory. */
static int shell_pass(const Scene *sc, int64_t s0, int64_t s1, const double *slo, const double *shi, uint64_t bit,
                      int threads, Cover cover, Crossings *cross, uint8_t *unsure)
{
    const Grid *g = sc->g;
    const int64_t ny = g->shape[1], nz = g->shape[2], lines = ny * nz;
    int64_t base[3], last[3], n[3];
    ranges(g, slo, shi, g->grow, base, last);
    for (int k = 0; k < 3; k++)
        n[k] = last[k] + 1 - base[k];
    const int64_t cells = n[0] * n[1] * n[2], e0 = n[0] + 1, e1 = n[1] + 1, e2 = n[2] + 1;
    int pieces = s1 - s0 < THREAD_FACES ? 1 : pieces_for(s1 - s0, SHARE_FACES, threads),
        count = threads_for(pieces, threads);
    Share *w = calloc((size_t)count, sizeof *w);
    Crossings *more = calloc((size_t)count, sizeof *more);
    uint8_t *spare = malloc((size_t)cells);
    int ok = w && more && spare;
    for (int k = 0; ok && k < count; k++) {
        w[k] = (Share){sc, s0, s1, {base[0], base[1], base[2]}, {n[0], n[1], n[2]}, bit, calloc((size_t)cells, 1),
                       k ? calloc((size_t)lines, 1) : unsure, NULL, k ? &more[k] : cross, 1};
        ok &= w[k].point && w[k].unsure;
    }
    if (ok)
        in_pieces_by(pieces, count, mark_share, w);
    for (int k = 0; k < count; k++)
        ok &= w[k].ok;
    for (int k = 1; k < count && ok; k++) { /* the other shares into the first */
        for (int64_t c = 0; c < cells; c++)
            w[0].point[c] |= w[k].point[c];
        for (int64_t l = 0; l < lines; l++)
            unsure[l] |= w[k].unsure[l];
        if (w[k].diff && !w[0].diff)
            w[0].diff = w[k].diff, w[k].diff = NULL;
        else if (w[k].diff)
            for (int64_t c = 0; c < e0 * e1 * e2; c++)
                w[0].diff[c] += w[k].diff[c];
        for (size_t c = 0; c < more[k].n && ok; c++)
            ok = push(cross, more[k].at[c].key, more[k].at[c].bit);
    }
    if (ok) {
        if (w[0].diff)
            summed(w[0].diff, e0, e1, e2);
        uint8_t *point = grow_cells(w[0].point, spare, n);
        const int32_t *diff = w[0].diff;
        for (int64_t x = 0; x < n[0]; x++)
            for (int64_t y = 0; y < n[1]; y++) {
                uint8_t *p = point + (x * n[1] + y) * n[2];
                if (diff) {
                    const int32_t *d = diff + (x * e1 + y) * e2;
                    for (int64_t z = 0; z < n[2]; z++)
                        p[z] |= d[z] > 0;
                }
                cover_or(cover, ((x + base[0]) * ny + y + base[1]) * nz + base[2], p, n[2], bit);
            }
    }
    free(spare);
    for (int k = 0; w && more && k < count; k++) {
        free(w[k].point), free(w[k].diff), free(more[k].at);
        if (k)
            free(w[k].unsure);
    }
    free(w), free(more);
    return ok;
}

typedef struct {
    int64_t run;
    double volume;
} Shell;

static int cmp_shell(const void *p, const void *q)
{
    const Shell *a = p, *b = q;
    if (a->volume != b->volume)
        return a->volume > b->volume ? -1 : 1;
    return (a->run > b->run) - (a->run < b->run);
}

/* the part order of faces (F,) of parts ``part`` (stable), or NULL (*fail unset) when they are in it */
static int64_t *part_order(const int64_t *part, npy_intp nf, int64_t np_, int *fail)
{
    npy_intp i = 1;
    while (i < nf && part[i] >= part[i - 1])
        i++;
    if (i >= nf)
        return NULL;
    int64_t *sorted = malloc(sizeof(int64_t) * (size_t)nf), *count = calloc((size_t)np_ + 1, sizeof(int64_t));
    if (!sorted || !count) {
        free(sorted), free(count);
        *fail = 1;
        return NULL;
    }
    for (i = 0; i < nf; i++)
        count[part[i] + 1]++;
    for (int64_t p = 0; p < np_; p++)
        count[p + 1] += count[p];
    for (i = 0; i < nf; i++)
        sorted[count[part[i]]++] = i;
    free(count);
    return sorted;
}

/* One share of the faces (in part order) for find_shells: the box and
 * finiteness of each run it holds whole, written in place, and of the (at most two) runs
 * it shares with its neighbours, kept apart to be merged. */
typedef struct {
    int64_t run;
    double lo[3], hi[3];
    uint8_t fin;
} RunBox;

typedef struct {
    const Scene *sc;
    uint8_t *fin;
    double limit;
    const int64_t *starts;
    int64_t runs, nf;
    double *slo, *shi;
    uint8_t *runfin;
    RunBox (*edge)[2]; /* per share */
    int *edges;
} Boxes;

static void box_share(void *arg, int k, int count)
{
    Boxes *w = arg;
    int64_t i0, i1;
    share(w->nf, k, count, &i0, &i1);
    w->edges[k] = 0;
    if (i0 >= i1)
        return;
    int64_t lo_r = 0, hi_r = w->runs; /* the run holding face i0: starts[r] <= i0 < starts[r + 1] */
    while (hi_r - lo_r > 1) {
        int64_t mid = (lo_r + hi_r) / 2;
        if (w->starts[mid] <= i0)
            lo_r = mid;
        else
            hi_r = mid;
    }
    for (int64_t r = lo_r; r < w->runs && w->starts[r] < i1; r++) {
        int64_t s0 = w->starts[r] > i0 ? w->starts[r] : i0, s1 = w->starts[r + 1] < i1 ? w->starts[r + 1] : i1;
        double a[3], b[3], c[3][3], lo[3], hi[3];
        uint8_t fin = 1;
        for (int64_t s = s0; s < s1; s++) {
            corners(w->sc, s, c, lo, hi);
            uint8_t usable = 1; /* no coordinate past the limit, none NaN */
            for (int v = 0; v < 3; v++)
                for (int d = 0; d < 3; d++)
                    usable &= fabs(c[v][d]) <= w->limit;
            w->fin[s] = usable;
            fin &= usable;
            for (int d = 0; d < 3; d++) {
                a[d] = s == s0 || lo[d] < a[d] ? lo[d] : a[d];
                b[d] = s == s0 || hi[d] > b[d] ? hi[d] : b[d];
            }
        }
        if (s0 == w->starts[r] && s1 == w->starts[r + 1]) {
            memcpy(w->slo + 3 * r, a, sizeof a), memcpy(w->shi + 3 * r, b, sizeof b);
            w->runfin[r] = fin;
        } else {
            RunBox *e = &w->edge[k][w->edges[k]++];
            e->run = r, e->fin = fin;
            memcpy(e->lo, a, sizeof a), memcpy(e->hi, b, sizeof b);
        }
    }
}

/* the shells: runs of faces in part order (starts (runs + 1,)) of a closed part whose faces
 * are all usable (fin (nf,): each face's corners within ``limit``, found here), with their
 * boxes slo, shi (3 runs,), largest volume first, with the boxes of every shell kept for
 * the grid: returns how many */
static int64_t find_shells(const Scene *sc, const int64_t *part, const uint8_t *closed, uint8_t *fin, double limit,
                           const int64_t *starts, int64_t runs, int64_t nf, int threads, double *slo, double *shi,
                           uint8_t *isshell, Shell *shells)
{
    int count = nf < THREAD_FACES ? 1 : pieces_for(nf, SHARE_FACES, threads);
    Boxes box = {.sc = sc, .fin = fin, .limit = limit, .starts = starts, .runs = runs, .nf = nf, .slo = slo,
                 .shi = shi, .runfin = isshell, .edge = malloc(sizeof *box.edge * (size_t)count),
                 .edges = malloc(sizeof *box.edges * (size_t)count)}, *w = &box;
    if (!box.edge || !box.edges) {
        free(box.edge), free(box.edges);
        return -1;
    }
    in_pieces(count, threads, box_share, w);
    int64_t last = -1; /* runs split between shares: their boxes merged */
    for (int k = 0; k < count; k++)
        for (int e = 0; e < w->edges[k]; e++) {
            const RunBox *p = &w->edge[k][e];
            double *a = slo + 3 * p->run, *b = shi + 3 * p->run;
            if (p->run != last) {
                memcpy(a, p->lo, sizeof p->lo), memcpy(b, p->hi, sizeof p->hi);
                isshell[p->run] = p->fin;
                last = p->run;
                continue;
            }
            for (int d = 0; d < 3; d++) {
                a[d] = p->lo[d] < a[d] ? p->lo[d] : a[d];
                b[d] = p->hi[d] > b[d] ? p->hi[d] : b[d];
            }
            isshell[p->run] &= p->fin;
        }
    free(box.edge), free(box.edges);
    int64_t n = 0;
    for (int64_t r = 0; r < runs; r++) {
        isshell[r] = (uint8_t)(isshell[r] && closed[part[face_at(sc, starts[r])]]);
        if (!isshell[r])
            continue;
        const double *a = slo + 3 * r, *b = shi + 3 * r;
        shells[n].run = r;
        shells[n++].volume = (b[0] - a[0]) * (b[1] - a[1]) * (b[2] - a[2]);
    }
    qsort(shells, (size_t)n, sizeof *shells, cmp_shell);
    return n;
}

/* the grid over every shell's box (enclosure.Grid) */
static void make_grid(Grid *g, const double *slo, const double *shi, const uint8_t *isshell, int64_t runs, int cells,
                      double offset)
{
    double glo[3], ghi[3], ext = 0.0;
    for (int k = 0; k < 3; k++) {
        glo[k] = INFINITY, ghi[k] = -INFINITY;
        for (int64_t r = 0; r < runs; r++)
            if (isshell[r]) {
                glo[k] = slo[3 * r + k] < glo[k] ? slo[3 * r + k] : glo[k];
                ghi[k] = shi[3 * r + k] > ghi[k] ? shi[3 * r + k] : ghi[k];
            }
        ext = ghi[k] - glo[k] > ext ? ghi[k] - glo[k] : ext;
    }
    g->step = (ext < 1e-300 ? 1e-300 : ext) / cells;
    for (int k = 0; k < 3; k++) {
        g->origin[k] = glo[k] - g->step;
        g->shape[k] = to_i64(ceil((ghi[k] - glo[k]) / g->step) + 3);
    }
    g->grow = 2.0 * offset + 1e-9 * g->step;
}

/* table (nx + 1, ny + 1, nz + 1): the summed-area table of the hidden cells, those of
 * odd parity for a shell not marked in ``cover`` on a line not ``unsure``. A cell's
 * parity is the XOR of the bits of the crossings (sorted by key) whose key lies in
 * [its line, its probe point) (enclosure.line_parity). The threads take ranges of lines
 * (the cells first), then of x slabs (their sums along z and y), then of lines again
 * (the sums along x): integers, so the order of the sums changes nothing. */
typedef struct {
    const Grid *g;
    const Crossings *cross;
    const uint64_t *prefix;
    Cover cover;
    const uint8_t *unsure;
    double probe;
    int32_t *table;
    size_t *at, *before;
} Table;

static void hidden_cells(void *arg, int k, int count)
{
    const Table *w = arg;
    const Grid *g = w->g;
    const Crossings *cross = w->cross;
    const int64_t nx = g->shape[0], nz = g->shape[2], lines = g->shape[1] * nz;
    const int64_t sy = (g->shape[1] + 1) * (nz + 1), sz = nz + 1;
    const double width = (double)nx + 2.0;
    int64_t l0, l1;
    share(lines, k, count, &l0, &l1);
    if (l0 >= l1)
        return;
    size_t lo = 0, hi = cross->n; /* the first crossing of line l0: key >= l0 */
    while (lo < hi) {
        size_t mid = lo + (hi - lo) / 2;
        if (cross->at[mid].key < (double)l0)
            lo = mid + 1;
        else
            hi = mid;
    }
    for (int64_t l = l0; l < l1; l++) {
        while (lo < cross->n && cross->at[lo].key < (double)l)
            lo++;
        w->at[l] = w->before[l] = lo;
    }
    for (int64_t x = 0; x < nx; x++) {
        int32_t *slab = w->table + (x + 1) * sy;
        for (int64_t l = l0; l < l1; l++) {
            double cell = (double)l + ((double)x + w->probe) / width;
            size_t before = w->before[l];
            while (before < cross->n && cross->at[before].key < cell)
                before++;
            w->before[l] = before;
            slab[(l / nz + 1) * sz + l % nz + 1] =
                ((w->prefix[before] ^ w->prefix[w->at[l]]) & ~cover_get(w->cover, x * lines + l)) != 0 &&
                !w->unsure[l];
        }
    }
}

static void sum_slabs(void *arg, int k, int count)
{
    const Table *w = arg;
    const int64_t ny = w->g->shape[1], nz = w->g->shape[2], sy = (ny + 1) * (nz + 1), sz = nz + 1;
    int64_t x0, x1;
    share(w->g->shape[0], k, count, &x0, &x1);
    for (int64_t x = x0 + 1; x < x1 + 1; x++) {
        int32_t *slab = w->table + x * sy;
        for (int64_t y = 1; y <= ny; y++)
            for (int64_t z = 2; z <= nz; z++)
                slab[y * sz + z] += slab[y * sz + z - 1];
        for (int64_t y = 2; y <= ny; y++)
            for (int64_t z = 1; z <= nz; z++)
                slab[y * sz + z] += slab[(y - 1) * sz + z];
    }
}

static void sum_across(void *arg, int k, int count)
{
    const Table *w = arg;
    const int64_t nx = w->g->shape[0], sy = (w->g->shape[1] + 1) * (w->g->shape[2] + 1);
    int64_t c0, c1;
    share(sy, k, count, &c0, &c1);
    for (int64_t x = 2; x <= nx; x++)
        for (int64_t c = c0; c < c1; c++)
            w->table[x * sy + c] += w->table[(x - 1) * sy + c];
}

static int hidden_table(const Grid *g, const Crossings *cross, const uint64_t *prefix, Cover cover,
                        const uint8_t *unsure, double probe, int threads, int32_t *table)
{
    const int64_t lines = g->shape[1] * g->shape[2];
    Table w = {g, cross, prefix, cover, unsure, probe, table, malloc(sizeof(size_t) * (size_t)lines),
               malloc(sizeof(size_t) * (size_t)lines)};
    if (!w.at || !w.before) {
        free(w.at), free(w.before);
        return 0;
    }
    int many = g->shape[0] * lines < 4 * THREAD_FACES ? 1 : threads;
    in_pieces(pieces_for(lines, SHARE_FACES, many), many, hidden_cells, &w);
    in_pieces(pieces_for(g->shape[0], 1, many), many, sum_slabs, &w);
    in_pieces(pieces_for((g->shape[1] + 1) * (g->shape[2] + 1), SHARE_FACES, many), many, sum_across, &w);
    free(w.at), free(w.before);
    return 1;
}

/* What certify's per-face steps share, each split between the threads */
typedef struct {
    const Scene *sc;
    int64_t nf;
    uint8_t *fin, *maybe, *out;
    const int64_t *starts;
    const double *slo, *shi;
    const Shell *shells;
    int used;
    const int32_t *table;
    int64_t *candidates; /* per share */
} Faces;

/* a face can be enclosed only by a shell other than its own whose box holds its box */
static void maybe_share(void *arg, int k, int count)
{
    Faces *w = arg;
    int64_t s0, s1, n = 0;
    share(w->nf, k, count, &s0, &s1);
    for (int64_t s = s0; s < s1; s++) {
        if (!w->fin[s])
            continue;
        double c[3][3], l[3], h[3];
        corners(w->sc, s, c, l, h);
        for (int i = 0; i < w->used && !w->maybe[s]; i++) {
            int64_t r = w->shells[i].run;
            const double *a = w->slo + 3 * r, *b = w->shi + 3 * r;
            w->maybe[s] = (s >= w->starts[r + 1] || s < w->starts[r]) && l[0] > a[0] && l[1] > a[1] &&
                          l[2] > a[2] && h[0] < b[0] && h[1] < b[1] && h[2] < b[2];
        }
        n += w->maybe[s];
    }
    w->candidates[k] = n;
}

/* the faces whose grown box's cells are all hidden (summed-area table); in blocks taken
 * by the threads as they finish the last, since the candidates may be all in one place
 * (an inner shell) */
#define FINAL_BLOCK 4096

static void final_share(void *arg, int k, int count)
{
    Faces *w = arg;
    const Grid *g = w->sc->g;
    const int64_t sy = (g->shape[1] + 1) * (g->shape[2] + 1), sz = g->shape[2] + 1;
    (void)count;
    int64_t s0 = (int64_t)k * FINAL_BLOCK, s1 = s0 + FINAL_BLOCK < w->nf ? s0 + FINAL_BLOCK : w->nf;
    for (int64_t s = s0; s < s1; s++) {
        if (!w->maybe[s])
            continue;
        double c[3][3], lo[3], hi[3];
        int64_t a[3], b[3], total = 0;
        corners(w->sc, s, c, lo, hi);
        ranges(g, lo, hi, g->grow, a, b);
        for (int corner = 0; corner < 8; corner++) {
            int64_t x = corner & 1 ? b[0] + 1 : a[0], y = corner & 2 ? b[1] + 1 : a[1],
                    z = corner & 4 ? b[2] + 1 : a[2];
            int picked = (corner & 1) + ((corner >> 1) & 1) + ((corner >> 2) & 1);
            total += (3 - picked) % 2 ? -w->table[x * sy + y * sz + z] : w->table[x * sy + y * sz + z];
        }
        w->out[face_at(w->sc, s)] = total == (b[0] - a[0] + 1) * (b[1] - a[1] + 1) * (b[2] - a[2] + 1);
    }
}

/* enclosure.enclosed_faces into out (F,); 0 when out of memory */
static int certify(const double *v, const int64_t *faces, const int64_t *part, npy_intp nf,
                   const uint8_t *closed, double offset, int cells, int max_shells, const double *probe, double limit,
                   int threads, uint8_t *out)
{
    int ok = 0, fail = 0;
    int64_t *sorted = NULL, *starts = NULL, *candidates = NULL;
    double *slo = NULL, *shi = NULL;
    uint8_t *fin = NULL, *maybe = NULL, *unsure = NULL, *isshell = NULL;
    uint64_t *prefix = NULL;
    Cover cover = {NULL, 8};
    int32_t *table = NULL;
    Shell *shells = NULL;
    Crossings cross = {NULL, 0, 0};
    int64_t np_ = 0, runs = 0;
    threads = threads < 1 ? 1 : threads;
    const int many = nf < THREAD_FACES ? 1 : threads, shares = pieces_for(nf, SHARE_FACES, many);
    for (npy_intp i = 0; i < nf; i++)
        np_ = part[i] + 1 > np_ ? part[i] + 1 : np_;
    sorted = part_order(part, nf, np_, &fail);
    fin = malloc((size_t)nf);
    maybe = calloc((size_t)nf, 1);
    candidates = malloc(sizeof *candidates * (size_t)shares);
    if (fail || !fin || !maybe || !candidates)
        goto done;
    Grid g;
    Scene sc = {v, faces, sorted, probe, &g};
    Faces w = {.sc = &sc, .nf = nf, .fin = fin, .maybe = maybe, .out = out, .candidates = candidates};
    for (npy_intp s = 0; s < nf; s++)
        runs += s == 0 || part[face_at(&sc, s)] != part[face_at(&sc, s - 1)];
    starts = malloc(sizeof(int64_t) * ((size_t)runs + 1));
    slo = malloc(sizeof(double) * 3 * (size_t)runs);
    shi = malloc(sizeof(double) * 3 * (size_t)runs);
    isshell = malloc((size_t)runs);
    shells = malloc(sizeof(Shell) * (size_t)runs);
    if (!starts || !slo || !shi || !isshell || !shells)
        goto done;
    for (npy_intp s = 0, r = 0; s < nf; s++)
        if (s == 0 || part[face_at(&sc, s)] != part[face_at(&sc, s - 1)])
            starts[r++] = s;
    starts[runs] = nf;
    int64_t nshell = find_shells(&sc, part, closed, fin, limit, starts, runs, nf, threads, slo, shi, isshell, shells);
    if (nshell < 0)
        goto done;
    w.used = nshell < max_shells ? (int)nshell : max_shells;
    w.starts = starts, w.slo = slo, w.shi = shi, w.shells = shells;
    int64_t maybes = 0;
    if (w.used) {
        in_pieces(shares, many, maybe_share, &w);
        for (int k = 0; k < shares; k++)
            maybes += w.candidates[k];
    }
    if (!maybes) {
        ok = 1;
        goto done;
    }
    make_grid(&g, slo, shi, isshell, runs, cells, offset);
    if (!(g.grow < g.step)) { /* cells finer than the rays' offset resolve nothing */
        ok = 1;
        goto done;
    }
    const int64_t nx = g.shape[0], ny = g.shape[1], nz = g.shape[2], lines = ny * nz;
    cover.width = w.used <= 8 ? 1 : w.used <= 16 ? 2 : w.used <= 32 ? 4 : 8;
    cover.at = calloc((size_t)(nx * lines), (size_t)cover.width);
    unsure = calloc((size_t)lines, 1);
    table = calloc((size_t)((nx + 1) * (ny + 1) * (nz + 1)), sizeof(int32_t));
    if (!cover.at || !unsure || !table)
        goto done;
    for (int i = 0; i < w.used; i++) {
        int64_t r = shells[i].run;
        uint64_t bit = (uint64_t)1 << i;
        if (!shell_pass(&sc, starts[r], starts[r + 1], slo + 3 * r, shi + 3 * r, bit, threads, cover, &cross, unsure))
            goto done;
    }
    if (cross.n)
        qsort(cross.at, cross.n, sizeof *cross.at, cmp_key);
    if (!(prefix = malloc(sizeof(uint64_t) * (cross.n + 1))))
        goto done;
    prefix[0] = 0;
    for (size_t c = 0; c < cross.n; c++)
        prefix[c + 1] = prefix[c] ^ cross.at[c].bit;
    if (!hidden_table(&g, &cross, prefix, cover, unsure, probe[0], threads, table))
        goto done;
    w.table = table;
    in_pieces((int)((nf + FINAL_BLOCK - 1) / FINAL_BLOCK), many, final_share, &w);
    ok = 1;
done:
    free(sorted), free(starts), free(slo), free(shi), free(fin), free(maybe), free(unsure);
    free(isshell), free(cover.at), free(prefix), free(table), free(shells), free(cross.at), free(candidates);
    return ok;
}

PyDoc_STRVAR(enclosed_doc, "enclosed(vertices (V,3) f8, faces (F,3) i8, part (F,) i8, closed (P,) u1, offset, cells, "
                           "max_shells, probe_x, probe_y, probe_z, limit, threads, out (F,) u1): enclosure.enclosed_faces "
                           "into out (the same for any thread count).");

static PyObject *enclosed(PyObject *self, PyObject *args)
{
    PyObject *ov, *of, *op, *oc, *oo;
    PyArrayObject *va, *fa, *pa, *ca, *outa;
    double offset, probe[3], limit;
    int cells, max_shells, threads;
    if (!PyArg_ParseTuple(args, "OOOOdiiddddiO", &ov, &of, &op, &oc, &offset, &cells, &max_shells, &probe[0],
                          &probe[1], &probe[2], &limit, &threads, &oo) ||
        !get3(ov, NPY_FLOAT64, &va, "vertices") || !get3(of, NPY_INT64, &fa, "faces") ||
        !get(oc, NPY_UINT8, -1, &ca, "closed"))
        return NULL;
    npy_intp nv = PyArray_SIZE(va) / 3, nf = PyArray_SIZE(fa) / 3, np_ = PyArray_SIZE(ca);
    if (!get(op, NPY_INT64, nf, &pa, "part") || !get(oo, NPY_UINT8, nf, &outa, "out"))
        return NULL;
    if (cells < 1 || cells > 1024 || max_shells < 0 || max_shells > 64 || !(offset >= 0.0)) {
        PyErr_SetString(PyExc_ValueError, "enclosed: bad parameters");
        return NULL;
    }
    const int64_t *f = PyArray_DATA(fa), *part = PyArray_DATA(pa);
    for (npy_intp i = 0; i < 3 * nf; i++)
        if (f[i] < 0 || f[i] >= nv) {
            PyErr_SetString(PyExc_ValueError, "enclosed: face index out of range");
            return NULL;
        }
    for (npy_intp i = 0; i < nf; i++)
        if (part[i] < 0 || part[i] >= np_) {
            PyErr_SetString(PyExc_ValueError, "enclosed: part out of range");
            return NULL;
        }
    uint8_t *out = PyArray_DATA(outa);
    memset(out, 0, (size_t)nf);
    if (!nf)
        Py_RETURN_NONE;
    int ok;
    Py_BEGIN_ALLOW_THREADS
    ok = certify(PyArray_DATA(va), f, part, nf, PyArray_DATA(ca), offset, cells, max_shells, probe, limit, threads,
                 out);
    Py_END_ALLOW_THREADS
    if (!ok)
        return PyErr_NoMemory();
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"parts", parts, METH_VARARGS, parts_doc},
    {"enclosed", enclosed, METH_VARARGS, enclosed_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cenclosure", "Compiled enclosure certificate, the same faces as enclosure.py's NumPy path.",
    -1, methods,
};

PyMODINIT_FUNC PyInit__cenclosure(void)
{
    import_array();
    return PyModule_Create(&module);
}
