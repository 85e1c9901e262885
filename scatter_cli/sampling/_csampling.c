/* Compiled face selection and placement: the same numbers as sampling.py's NumPy path.
 *
 * Every function does, point by point, the float64 operations the NumPy code does on
 * whole arrays, in the same order (built with -ffp-contract=off: no fused multiply-add),
 * so the two paths give byte-identical output. The GIL is released while they run, so
 * the chunk threads of sampling.run_chunks work in parallel.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include "_ckernel.h"
#include <math.h>
#include <stdint.h>
#include <string.h>


/* The guide entry as int64 whatever the table's integer width. */
static inline int64_t guide_at(const void *guide, int wide, int64_t k)
{
    return wide ? ((const int64_t *)guide)[k] : ((const int32_t *)guide)[k];
}

#define BLOCK 256
/* Faces for u[k * width] (k < n) into out: searchsorted(cdf, u * total, 'right') clipped
 * to the last face, started from the guide. Done in passes over a block, so the cache
 * misses of a pass are independent of each other and overlap: all the guide entries
 * first, then one CDF step for the draws whose bucket straddles a face boundary, then
 * the rare longer searches. */
static void select_block(const double *cdf, int64_t last, const void *guide, int wide, int64_t m,
                         const double *u, int width, int64_t n, int64_t *out)
{
    double total = cdf[last];
    int64_t open[BLOCK], nopen = 0;
    for (int64_t k = 0; k < n; k++) {
        int64_t g = guide_at(guide, wide, (int64_t)(u[k * width] * (double)m));
        out[k] = g >= 0 ? g : -1 - g;
        open[nopen] = k;
        nopen += g < 0;
    }
    for (int64_t t = 0; t < nopen; t++) {
        int64_t k = open[t], i = out[k];
        double x = u[k * width] * total;
        while (i < last && cdf[i] <= x)
            i++;
        out[k] = i;
    }
}

/* Where a face's corners come from: rows of a (R, 9) corner table, or three rows of a
 * (V, 3) vertex array picked by a (F, 3) int64 face array. ``rows`` (optional) maps a
 * used-face number to its row or face. */
typedef struct {
    const double *coords;
    const int64_t *faces, *rows;
} Corners;

static inline void corners_of(const Corners *c, int64_t used, double t[9])
{
    int64_t r = c->rows ? c->rows[used] : used;
    if (!c->faces) {
        memcpy(t, c->coords + 9 * r, 9 * sizeof(double));
        return;
    }
    for (int k = 0; k < 3; k++)
        memcpy(t + 3 * k, c->coords + 3 * c->faces[3 * r + k], 3 * sizeof(double));
}

/* Parse (coords, faces, rows): faces and rows may be None. */
static int get_corners(PyObject *ocoords, PyObject *ofaces, PyObject *orows, Corners *c)
{
    PyArrayObject *coords_a, *faces_a = NULL, *rows_a = NULL;
    if (!get(ocoords, NPY_FLOAT64, -1, &coords_a, "corners") ||
        (ofaces != Py_None && !get(ofaces, NPY_INT64, -1, &faces_a, "faces")) ||
        (orows != Py_None && !get(orows, NPY_INT64, -1, &rows_a, "rows")))
        return 0;
    c->coords = PyArray_DATA(coords_a);
    c->faces = faces_a ? PyArray_DATA(faces_a) : NULL;
    c->rows = rows_a ? PyArray_DATA(rows_a) : NULL;
    return 1;
}

/* points = (t1 - t0) b1 + (t2 - t0) b2 + t0, column by column as _corner_points does. */
static inline void place_one(const double *t, double b1, double b2, double *p)
{
    for (int c = 0; c < 3; c++) {
        double col = (t[3 + c] - t[c]) * b1;
        col += (t[6 + c] - t[c]) * b2;
        col += t[c];
        p[c] = col;
    }
}

PyDoc_STRVAR(bounds_doc,
"bounds(vertices, out)\n\n"
"The minimum and maximum of each column of vertices (n, 3) float64, n > 0, into out\n"
"(2, 3) float64: surface.column_bounds's values bit for bit. Row after row as NumPy's\n"
"minimum and maximum reduce: of equal values the later (so signed zeros as NumPy gives\n"
"them), and NaN wins.");

#define MIN_OF(a, x) (((a) < (x) || (a) != (a)) ? (a) : (x)) /* np.minimum(a, x) */
#define MAX_OF(a, x) (((a) > (x) || (a) != (a)) ? (a) : (x))

/* Four runs of consecutive rows, each reduced in turn, then the four in order: the same
 * values as one run (of equal values the later still wins, the first NaN still wins),
 * with four independent chains of comparisons instead of one. */
static void bounds_of(const double *v, npy_intp n, double *out)
{
    npy_intp m = n < 8 ? n : n / 4, runs = n < 8 ? 1 : 4;
    double lo[4][3], hi[4][3];
    for (npy_intp k = 0; k < runs; k++)
        for (int c = 0; c < 3; c++)
            lo[k][c] = hi[k][c] = v[3 * k * m + c];
    for (npy_intp r = 1; r < m; r++)
        for (npy_intp k = 0; k < runs; k++)
            for (int c = 0; c < 3; c++) {
                double x = v[3 * (k * m + r) + c];
                lo[k][c] = MIN_OF(lo[k][c], x);
                hi[k][c] = MAX_OF(hi[k][c], x);
            }
    for (npy_intp r = runs * m; r < n; r++) /* the rows left over: the last run's */
        for (int c = 0; c < 3; c++) {
            lo[runs - 1][c] = MIN_OF(lo[runs - 1][c], v[3 * r + c]);
            hi[runs - 1][c] = MAX_OF(hi[runs - 1][c], v[3 * r + c]);
        }
    for (int c = 0; c < 3; c++) {
        out[c] = lo[0][c];
        out[3 + c] = hi[0][c];
        for (npy_intp k = 1; k < runs; k++) {
            out[c] = MIN_OF(out[c], lo[k][c]);
            out[3 + c] = MAX_OF(out[3 + c], hi[k][c]);
        }
    }
}

static PyObject *bounds(PyObject *self, PyObject *args)
{
    PyObject *ov, *oout;
    PyArrayObject *v_a, *out_a;
    npy_intp n;
    if (!PyArg_ParseTuple(args, "OO", &ov, &oout) || !get_rows(ov, NPY_FLOAT64, 3, &v_a, &n, "vertices") ||
        !get(oout, NPY_FLOAT64, 6, &out_a, "out"))
        return NULL;
    if (n < 1) {
        PyErr_SetString(PyExc_ValueError, "bounds: no rows");
        return NULL;
    }
    const double *v = PyArray_DATA(v_a);
    double *out = PyArray_DATA(out_a);
    Py_BEGIN_ALLOW_THREADS
    bounds_of(v, n, out);
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

PyDoc_STRVAR(areas_doc,
"areas(vertices, faces, cof, out)\n\n"
"Twice the area of each face (F, 3) int64 of vertices (V, 3) float64 into out (F,)\n"
"float64, under the cofactor matrix cof (3, 3) float64 or None: surface.doubled_areas\n"
"of the corners, operation for operation. Raises ValueError for a vertex index out of\n"
"range (the other kernels trust the faces this one has read).");

/* (t1 - t0) x (t2 - t0) of face f: surface.face_cross. */
static inline void face_cross(const Corners *c, npy_intp f, const double *center, double x[3])
{
    double t[9], e1[3], e2[3];
    corners_of(c, f, t);
    if (center) /* the corners less center first (visibility.py centres the scene) */
        for (int k = 0; k < 9; k++)
            t[k] -= center[k % 3];
    for (int k = 0; k < 3; k++) {
        e1[k] = t[3 + k] - t[k];
        e2[k] = t[6 + k] - t[k];
    }
    for (int k = 0; k < 3; k++) {
        int a = (k + 1) % 3, b = (k + 2) % 3;
        x[k] = e1[a] * e2[b] - e1[b] * e2[a];
    }
}

/* Parse vertices (V, 3) float64 and n faces (n, 3) int64 into c, every index checked
 * (ValueError when out of range). */
static int get_faces(PyObject *overts, PyObject *ofaces, npy_intp n, Corners *c)
{
    PyArrayObject *verts_a, *faces_a;
    if (!get(overts, NPY_FLOAT64, -1, &verts_a, "vertices") || !get(ofaces, NPY_INT64, 3 * n, &faces_a, "faces"))
        return 0;
    *c = (Corners){PyArray_DATA(verts_a), PyArray_DATA(faces_a), NULL};
    uint64_t nv = (uint64_t)(PyArray_SIZE(verts_a) / 3), bad = 0;
    for (npy_intp k = 0; k < 3 * n; k++)
        bad |= (uint64_t)c->faces[k] >= nv;
    if (bad)
        PyErr_SetString(PyExc_ValueError, "face indices out of range");
    return !bad;
}

static PyObject *areas(PyObject *self, PyObject *args)
{
    PyObject *overts, *ofaces, *ocof, *oout;
    PyArrayObject *cof_a = NULL, *out_a;
    Corners c;
    if (!PyArg_ParseTuple(args, "OOOO", &overts, &ofaces, &ocof, &oout) || !get(oout, NPY_FLOAT64, -1, &out_a, "out") ||
        (ocof != Py_None && !get(ocof, NPY_FLOAT64, 9, &cof_a, "cof")) ||
        !get_faces(overts, ofaces, PyArray_SIZE(out_a), &c))
        return NULL;
    npy_intp n = PyArray_SIZE(out_a);
    const double *m = cof_a ? PyArray_DATA(cof_a) : NULL;
    double *out = PyArray_DATA(out_a);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp f = 0; f < n; f++) {
        double x[3];
        face_cross(&c, f, NULL, x);
        if (m) { /* surface.apply_matrix */
            double y[3];
            for (int k = 0; k < 3; k++) {
                double col = m[3 * k] * x[0];
                col += m[3 * k + 1] * x[1];
                col += m[3 * k + 2] * x[2];
                y[k] = col;
            }
            memcpy(x, y, sizeof(y));
        }
        double s = x[0] * x[0] + x[1] * x[1];
        s += x[2] * x[2];
        out[f] = sqrt(s);
    }
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

PyDoc_STRVAR(unit_normals_doc,
"unit_normals(vertices, faces, out, center)\n\n"
"The unit normal of each face (F, 3) int64 of vertices (V, 3) float64 less center (3,)\n"
"float64 into out (F, 3) float64, zero where it is not finite: normals.face_normals,\n"
"operation for operation. Raises ValueError for a vertex index out of range.");

static PyObject *unit_normals(PyObject *self, PyObject *args)
{
    PyObject *overts, *ofaces, *oout, *ocenter;
    PyArrayObject *out_a, *center_a;
    Corners c;
    if (!PyArg_ParseTuple(args, "OOOO", &overts, &ofaces, &oout, &ocenter) ||
        !get(oout, NPY_FLOAT64, -1, &out_a, "out") || !get(ocenter, NPY_FLOAT64, 3, &center_a, "center") ||
        !get_faces(overts, ofaces, PyArray_SIZE(out_a) / 3, &c))
        return NULL;
    npy_intp n = PyArray_SIZE(out_a) / 3;
    double *out = PyArray_DATA(out_a);
    const double *center = PyArray_DATA(center_a);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp f = 0; f < n; f++) {
        double x[3];
        face_cross(&c, f, center, x);
        double s = x[0] * x[0] + x[1] * x[1];
        s += x[2] * x[2];
        s = sqrt(s);
        for (int k = 0; k < 3; k++) {
            double q = x[k] / s;
            out[3 * f + k] = isfinite(q) ? q : 0.0;
        }
    }
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

PyDoc_STRVAR(guide_doc,
"guide(cdf, out, start, stop)\n\n"
"Fill entries start .. stop - 1 of the guide table out (m,) int32 or int64 for cdf (F,)\n"
"float64, as sampling._guide_table: entry k is the first face whose CDF exceeds\n"
"k / m * total, stored as is when bucket k + 1 starts on the same face, else as\n"
"-1 - face. Disjoint ranges can be filled at once on several threads.");

static PyObject *guide(PyObject *self, PyObject *args)
{
    PyObject *ocdf, *oout;
    PyArrayObject *cdf_a, *out_a;
    Py_ssize_t start, stop;
    if (!PyArg_ParseTuple(args, "OOnn", &ocdf, &oout, &start, &stop) || !get(ocdf, NPY_FLOAT64, -1, &cdf_a, "cdf"))
        return NULL;
    int wide = PyArray_Check(oout) && PyArray_TYPE((PyArrayObject *)oout) == NPY_INT64;
    if (!get(oout, wide ? NPY_INT64 : NPY_INT32, -1, &out_a, "out"))
        return NULL;
    const double *cdf = PyArray_DATA(cdf_a);
    int64_t n = PyArray_SIZE(cdf_a), m = PyArray_SIZE(out_a), last = n - 1;
    void *out = PyArray_DATA(out_a);
    if (n < 1)
        return PyErr_Format(PyExc_ValueError, "empty cdf");
    if (start < 0 || stop > m || start > stop)
        return PyErr_Format(PyExc_ValueError, "guide range out of bounds");
    if (m & (m - 1))
        return PyErr_Format(PyExc_ValueError, "the guide table's size must be a power of two");
    Py_BEGIN_ALLOW_THREADS
    double total = cdf[last];
    double lower = ((double)start / (double)m) * total;
    int64_t lo = 0, hi = n; /* the first face whose CDF exceeds bucket start's lower edge */
    while (lo < hi) {
        int64_t mid = lo + (hi - lo) / 2;
        if (cdf[mid] <= lower)
            lo = mid + 1;
        else
            hi = mid;
    }
    int64_t i = lo, prev = 0;
    double step = 1.0 / (double)m; /* m is a power of two: k * step is k / m exactly */
    for (int64_t k = start; k <= stop; k++) {
        lower = ((double)k * step) * total;
        i += i < n && cdf[i] <= lower; /* most buckets move on by one face at most: no branch */
        while (i < n && cdf[i] <= lower)
            i++;
        int64_t first = i < last ? i : last;
        if (k > start) {
            int64_t v = first == prev ? prev : -1 - prev;
            if (wide)
                ((int64_t *)out)[k - 1] = v;
            else
                ((int32_t *)out)[k - 1] = (int32_t)v;
        }
        prev = first;
    }
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

PyDoc_STRVAR(select_doc,
"select(cdf, guide, u, width, column, out)\n\n"
"out (n,) int64 = the face of u[:, column] for u (n, width) float64: SamplePlan.select.");

static PyObject *select_faces(PyObject *self, PyObject *args)
{
    PyObject *ocdf, *oguide, *ou, *oout;
    PyArrayObject *cdf_a, *guide_a, *u_a, *out_a;
    int width, column;
    if (!PyArg_ParseTuple(args, "OOOiiO", &ocdf, &oguide, &ou, &width, &column, &oout))
        return NULL;
    int wide = PyArray_Check(oguide) && PyArray_TYPE((PyArrayObject *)oguide) == NPY_INT64;
    if (!get(ocdf, NPY_FLOAT64, -1, &cdf_a, "cdf") || !get(oguide, wide ? NPY_INT64 : NPY_INT32, -1, &guide_a, "guide") ||
        !get(oout, NPY_INT64, -1, &out_a, "out"))
        return NULL;
    npy_intp n = PyArray_SIZE(out_a);
    if (width < 1 || column < 0 || column >= width || !get(ou, NPY_FLOAT64, n * width, &u_a, "u"))
        return NULL;
    const double *cdf = PyArray_DATA(cdf_a), *u = PyArray_DATA(u_a);
    const void *g = PyArray_DATA(guide_a);
    int64_t last = PyArray_SIZE(cdf_a) - 1, m = PyArray_SIZE(guide_a);
    int64_t *out = PyArray_DATA(out_a);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp k = 0; k < n; k += BLOCK)
        select_block(cdf, last, g, wide, m, u + k * width + column, width, n - k < BLOCK ? n - k : BLOCK, out + k);
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

PyDoc_STRVAR(place_doc,
"place(coords, faces, rows, used, b, points)\n\n"
"points (n, 3) float64 at barycentric b (n, 2) float64 on the used faces used (n,)\n"
"int64. Corners: coords (R, 9) float64 rows when faces is None, else vertices coords\n"
"(V, 3) float64 of faces (F, 3) int64; rows (optional, int64) maps used faces to those.");

static PyObject *place(PyObject *self, PyObject *args)
{
    PyObject *ocoords, *ofaces, *orows, *oused, *ob, *opts;
    PyArrayObject *used_a, *b_a, *pts_a;
    Corners c;
    if (!PyArg_ParseTuple(args, "OOOOOO", &ocoords, &ofaces, &orows, &oused, &ob, &opts) ||
        !get_corners(ocoords, ofaces, orows, &c) || !get(oused, NPY_INT64, -1, &used_a, "used"))
        return NULL;
    npy_intp n = PyArray_SIZE(used_a);
    if (!get(ob, NPY_FLOAT64, 2 * n, &b_a, "b") || !get(opts, NPY_FLOAT64, 3 * n, &pts_a, "points"))
        return NULL;
    const double *b = PyArray_DATA(b_a);
    const int64_t *used = PyArray_DATA(used_a);
    double *pts = PyArray_DATA(pts_a);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp k = 0; k < n; k++) {
        double t[9];
        corners_of(&c, used[k], t);
        place_one(t, b[2 * k], b[2 * k + 1], pts + 3 * k);
    }
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

/* NumPy's PCG64DXSM: a 128-bit LCG with the cheap 64-bit multiplier, DXSM output taken
 * from the state before the step; Generator.random() is (next >> 11) * 2^-53. The kernel
 * draws the same doubles as sampling.uniforms, without writing them to memory. */
#define PCG_MULT 0xda942042e4dd58b5ULL
/* Uniforms a point takes from the stream: face choice, then the warp's two. Exported as
 * the module's DRAWS_PER_POINT, which tests hold equal to sampling.DRAWS_PER_POINT. */
#define DRAWS_PER_POINT 3

typedef struct {
    __uint128_t state, inc;
} Pcg;

static inline double pcg_double(Pcg *r)
{
    uint64_t hi = (uint64_t)(r->state >> 64), lo = (uint64_t)r->state | 1;
    hi ^= hi >> 32;
    hi *= PCG_MULT;
    hi ^= hi >> 48;
    hi *= lo;
    r->state = r->state * PCG_MULT + r->inc;
    return (double)(hi >> 11) * (1.0 / 9007199254740992.0);
}

/* What draw() fills: see its doc. */
typedef struct {
    const double *cdf;
    int64_t last;
    const void *guide;
    int wide;
    int64_t m;
    const Corners *c;
    int64_t *used;
    double *pts, *b;
} Draw;

/* Points at[j] (j < count; base + j when at is NULL) from their draws ub[DRAWS_PER_POINT j ..]. */
static void draw_block(const Draw *d, const double *ub, int64_t base, const int32_t *at, npy_intp count)
{
    const Corners *c = d->c;
    int64_t face[BLOCK];
    select_block(d->cdf, d->last, d->guide, d->wide, d->m, ub, DRAWS_PER_POINT, count, face);
    /* the face rows of the whole block first: their cache misses overlap, and so do
       the vertex rows' below, instead of each point waiting on its face row */
    int64_t vi[3 * BLOCK];
    if (c->faces)
        for (npy_intp j = 0; j < count; j++)
            memcpy(vi + 3 * j, c->faces + 3 * (c->rows ? c->rows[face[j]] : face[j]), 3 * sizeof(int64_t));
    for (npy_intp j = 0; j < count; j++) {
        int64_t k = at ? at[j] : base + j;
        double b1 = 1.0 - sqrt(ub[DRAWS_PER_POINT * j + 1]); /* warps.square_to_triangle */
        double b2 = (1.0 - b1) * ub[DRAWS_PER_POINT * j + 2];
        if (d->b) {
            d->b[2 * k] = b1;
            d->b[2 * k + 1] = b2;
        }
        double t[9];
        if (c->faces)
            for (int v = 0; v < 3; v++)
                memcpy(t + 3 * v, c->coords + 3 * vi[3 * j + v], 3 * sizeof(double));
        else
            corners_of(c, face[j], t);
        place_one(t, b1, b2, d->pts + 3 * k);
        d->used[k] = face[j];
    }
}

/* draw() for n points taken in the order of their first draw, which orders their faces
 * too, so the guide, CDF, face and vertex rows are read in a sweep rather than at random:
 * faster on a mesh larger than the caches. Each point's numbers are the same, only the
 * order they are computed in changes. All draws go first into the points array (three
 * doubles a point, each replaced by its point in the end); a counting sort on the first
 * draw's leading bits orders them. */
static int draw_sorted(const Draw *d, Pcg *rng, npy_intp n)
{
    int bits = 1;
    while (bits < 20 && ((npy_intp)8 << bits) < n)
        bits++;
    int64_t buckets = (int64_t)1 << bits;
    int32_t *start = calloc(buckets + 1, sizeof(int32_t)), *order = malloc(n * sizeof(int32_t));
    if (!start || !order) {
        free(start);
        free(order);
        return 0;
    }
    double *u = d->pts; /* room for the draws: DRAWS_PER_POINT is 3, as the coordinates */
    for (npy_intp j = 0; j < DRAWS_PER_POINT * n; j++)
        u[j] = pcg_double(rng);
    for (npy_intp k = 0; k < n; k++)
        start[(int64_t)(u[DRAWS_PER_POINT * k] * (double)buckets) + 1]++;
    for (int64_t q = 0; q < buckets; q++)
        start[q + 1] += start[q];
    for (npy_intp k = 0; k < n; k++)
        order[start[(int64_t)(u[DRAWS_PER_POINT * k] * (double)buckets)]++] = (int32_t)k;
    for (npy_intp k0 = 0; k0 < n; k0 += BLOCK) {
        npy_intp count = n - k0 < BLOCK ? n - k0 : BLOCK;
        double ub[DRAWS_PER_POINT * BLOCK];
        for (npy_intp j = 0; j < count; j++)
            memcpy(ub + DRAWS_PER_POINT * j, u + DRAWS_PER_POINT * (int64_t)order[k0 + j], DRAWS_PER_POINT * sizeof(double));
        draw_block(d, ub, 0, order + k0, count);
    }
    free(start);
    free(order);
    return 1;
}

PyDoc_STRVAR(draw_doc,
"draw(cdf, guide, state, coords, faces, rows, used, points, b, in_face_order)\n\n"
"The random method for n points: draws 3 k .. 3 k + 2 of the PCG64DXSM generator whose\n"
"state is (state_high, state_low, inc_high, inc_low) (four uint64) give point k's face\n"
"(into used (n,) int64) and its square-root warp (into b (n, 2) float64, or None when\n"
"the weights are not wanted); the point on the face goes into points (n, 3) float64.\n"
"Corners as for place(). The same bytes as SamplePlan.place(select(...), warp(...)).\n"
"in_face_order: compute the points in face order (faster on large meshes, same bytes).");

static PyObject *draw(PyObject *self, PyObject *args)
{
    PyObject *ocdf, *oguide, *ocoords, *ofaces, *orows, *oused, *opts, *ob;
    PyArrayObject *cdf_a, *guide_a, *used_a, *pts_a, *b_a = NULL;
    unsigned long long st_hi, st_lo, inc_hi, inc_lo;
    int in_face_order;
    Corners c;
    if (!PyArg_ParseTuple(args, "OO(KKKK)OOOOOOp", &ocdf, &oguide, &st_hi, &st_lo, &inc_hi, &inc_lo, &ocoords, &ofaces,
                          &orows, &oused, &opts, &ob, &in_face_order))
        return NULL;
    int wide = PyArray_Check(oguide) && PyArray_TYPE((PyArrayObject *)oguide) == NPY_INT64;
    if (!get(ocdf, NPY_FLOAT64, -1, &cdf_a, "cdf") || !get(oguide, wide ? NPY_INT64 : NPY_INT32, -1, &guide_a, "guide") ||
        !get_corners(ocoords, ofaces, orows, &c) || !get(oused, NPY_INT64, -1, &used_a, "used"))
        return NULL;
    npy_intp n = PyArray_SIZE(used_a);
    if (!get(opts, NPY_FLOAT64, 3 * n, &pts_a, "points") || (ob != Py_None && !get(ob, NPY_FLOAT64, 2 * n, &b_a, "b")))
        return NULL;
    Pcg rng = {((__uint128_t)st_hi << 64) | st_lo, ((__uint128_t)inc_hi << 64) | inc_lo};
    const double *cdf = PyArray_DATA(cdf_a);
    const void *g = PyArray_DATA(guide_a);
    int64_t last = PyArray_SIZE(cdf_a) - 1, m = PyArray_SIZE(guide_a);
    int64_t *used = PyArray_DATA(used_a);
    double *pts = PyArray_DATA(pts_a), *b = b_a ? PyArray_DATA(b_a) : NULL;
    Draw d = {cdf, last, g, wide, m, &c, used, pts, b};
    int ok = 1;
    Py_BEGIN_ALLOW_THREADS
    if (in_face_order && n >= 2 * BLOCK && n < INT32_MAX)
        ok = draw_sorted(&d, &rng, n);
    else
        for (npy_intp k0 = 0; k0 < n; k0 += BLOCK) {
            npy_intp count = n - k0 < BLOCK ? n - k0 : BLOCK;
            double ub[DRAWS_PER_POINT * BLOCK]; /* the draws of points k0 .. k0 + count - 1 */
            for (npy_intp j = 0; j < DRAWS_PER_POINT * count; j++)
                ub[j] = pcg_double(&rng);
            draw_block(&d, ub, k0, NULL, count);
        }
    Py_END_ALLOW_THREADS
    if (!ok)
        return PyErr_NoMemory();
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"areas", areas, METH_VARARGS, areas_doc},
    {"bounds", bounds, METH_VARARGS, bounds_doc},
    {"unit_normals", unit_normals, METH_VARARGS, unit_normals_doc},
    {"guide", guide, METH_VARARGS, guide_doc},
    {"select", select_faces, METH_VARARGS, select_doc},
    {"place", place, METH_VARARGS, place_doc},
    {"draw", draw, METH_VARARGS, draw_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_csampling",
    "Compiled face selection and placement, byte-identical to sampling.py's NumPy path.", -1, methods,
};

PyMODINIT_FUNC PyInit__csampling(void)
{
    import_array();
    PyObject *m = PyModule_Create(&module);
    if (m && PyModule_AddIntConstant(m, "DRAWS_PER_POINT", DRAWS_PER_POINT) < 0)
        Py_CLEAR(m);
    return m;
}
