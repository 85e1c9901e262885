/* Compiled winding numbers: the same sums as winding.py's NumPy path.
 *
 * winding(points, nodes, links, triangles, accuracy, order, threads, out): for each
 * point, the tree walked depth-first in preorder (a far node adds its expansion and its
 * subtree is skipped, a near leaf adds its triangles' solid angles one by one, a near
 * inner node opens), every term added to a sum started at 0. Every float64 operation
 * is the NumPy code's, in its order (built with -ffp-contract=off), the arctangent
 * included (Cephes' atan, + - * / only), so the two paths give the same bytes. The
 * points walk in a Morton order of their own (walk_order), four neighbours together, one
 * in each lane of a vector (see winding_4), shared among the threads in blocks; each
 * point's sum is its own, so the result depends on neither that order nor the threads.
 * The GIL is released while they run. The links are checked first: a subtree or a
 * leaf's triangles out of range, or subtrees that do not nest, raise ValueError.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include "_ckernel.h"
#include "_cmorton.h"
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include "_cthreads.h"

#define FIELDS 28
#define BLOCK 256 /* points a thread takes at a time */
#define DEPTH 256 /* subtrees at most, one in the other (a WindingTree: below 128) */

static const double INV2PI = 0.15915494309189535, INV4PI = 0.07957747154594767;
static const double PIO2 = 1.5707963267948966, PIO4 = 0.7853981633974483, PI = 3.141592653589793;
static const double MOREBITS = 6.123233995736765886130e-17, HALF_MOREBITS = 0.5 * 6.123233995736765886130e-17;
static const double TAN3PIO8 = 2.41421356237309504880;

/* what the walk reads at every node, in one cache line: the centre, the squared
 * distance beyond which the node is far ((accuracy * radius)^2, as the NumPy path
 * computes it), and the links */
typedef struct {
    double c[3], far2;
    int64_t skip, first, count, pad;
} Hot;

typedef struct {
    const double *points, *nodes, *tri;
    const Hot *hot;
    const int64_t *walk; /* the points' indices in the order they walk */
    int64_t n, count;
    int order;
    double *out;
    int64_t next; /* the next block to take (atomic) */
} Work;

/* ---- four points at a time ----
 *
 * Four neighbouring points walk the tree together, each lane of a vector holding one
 * point: the walk visits, in preorder, every node that any of the four would visit
 * alone (lane l's next node is next[l]; the walk goes to the least of them), and at each
 * node a lane whose own walk is there adds what it would add alone, in the same order
 * (the other lanes compute but keep their sum). At a near leaf that few lanes reach
 * (fewer than its triangles over four), each of them takes its triangles four at a time
 * instead, one in each lane, and adds their terms in turn. Every lane does the scalar
 * code's float64 operations in its order, so the sums are the same bytes. */

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wpsabi" /* vectors pass only between inlined functions */
#endif
typedef double v4d __attribute__((vector_size(32)));
typedef int64_t v4l __attribute__((vector_size(32)));

#define INLINE __attribute__((always_inline)) static inline

/* lanes of a where m is set, else of b */
INLINE v4d pick(v4l m, v4d a, v4d b) { return (v4d)(((v4l)a & m) | ((v4l)b & ~m)); }

INLINE v4d sqrt4(v4d x)
{
    for (int l = 0; l < 4; l++)
        x[l] = sqrt(x[l]);
    return x;
}

INLINE v4d abs4(v4d x) { return (v4d)((v4l)x & (v4l){INT64_MAX, INT64_MAX, INT64_MAX, INT64_MAX}); }

/* elementary.atan2 (the NumPy path's), lane by lane */
INLINE v4d atan2_4(v4d y, v4d x)
{
    v4d ay = abs4(y), ax = abs4(x), t, arg, z, a;
    t = pick(ax == 0, (v4d){INFINITY, INFINITY, INFINITY, INFINITY}, ay / ax);
    v4l small = t <= 0.66, large = t > TAN3PIO8;
    arg = pick(small, t, pick(large, (v4d){1, 1, 1, 1}, t - 1.0) / pick(large, t, t + 1.0)); /* (one division) */
    z = arg * arg;
    z = z * ((((-8.750608600031904122785e-01 * z + -1.615753718733365076637e+01) * z + -7.500855792314704667340e+01) * z +
              -1.228866684490136173410e+02) * z + -6.485021904942025371773e+01) /
        (((((z + 2.485846490142306297962e+01) * z + 1.650270098316988542046e+02) * z + 4.328810604912902668951e+02) * z +
          4.853903996359136964868e+02) * z + 1.945506571482613964425e+02);
    z = arg * z + arg;
    a = pick(small, z, pick(large, PIO2 - z + MOREBITS, PIO4 + z + HALF_MOREBITS));
    a = pick(ay == 0, (v4d){0, 0, 0, 0}, a);
    a = pick(x < 0, PI - a, a);
    return pick(y < 0, -a, a);
}

/* winding._triangle_terms, lane by lane, of the corners a, b, c less the point */
INLINE v4d solid_angle4(v4d ax, v4d ay, v4d az, v4d bx, v4d by, v4d bz, v4d cx, v4d cy, v4d cz)
{
    v4d la = sqrt4(ax * ax + ay * ay + az * az);
    v4d lb = sqrt4(bx * bx + by * by + bz * bz);
    v4d lc = sqrt4(cx * cx + cy * cy + cz * cz);
    v4d det = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx);
    v4d ab = ax * bx + ay * by + az * bz;
    v4d bc = bx * cx + by * cy + bz * cz;
    v4d ca = cx * ax + cy * ay + cz * az;
    v4d den = la * lb * lc + ab * lc + bc * la + ca * lb;
    return atan2_4(det, den) * INV2PI;
}

/* the terms of triangle t (9 doubles) at four points */
INLINE v4d triangle_term4(const double *t, v4d qx, v4d qy, v4d qz)
{
    return solid_angle4(t[0] - qx, t[1] - qy, t[2] - qz, t[3] - qx, t[4] - qy, t[5] - qz, t[6] - qx, t[7] - qy, t[8] - qz);
}

/* the terms of triangles t, t + 9, ... t + 9 (k - 1) at one point (x, y, z), in lanes
 * 0 .. k - 1 (the others: triangle t's again) */
INLINE v4d triangles_term4(const double *t, int k, double x, double y, double z)
{
    v4d c[9] = {{0}};
    for (int l = 0; l < 4; l++)
        for (int j = 0; j < 9; j++)
            c[j][l] = t[9 * (l < k ? l : 0) + j];
    return solid_angle4(c[0] - x, c[1] - y, c[2] - z, c[3] - x, c[4] - y, c[5] - z, c[6] - x, c[7] - y, c[8] - z);
}

/* winding._far_terms, lane by lane */
INLINE v4d far_term4(const double *f, v4d rx, v4d ry, v4d rz, v4d d2, int order)
{
    v4d id2 = 1.0 / d2;
    v4d id3 = id2 / sqrt4(d2);
    v4d w = (f[4] * rx + f[5] * ry + f[6] * rz) * id3;
    if (order >= 1) {
        v4d quad = (f[8] * rx + f[11] * ry + f[12] * rz) * rx + (f[9] * ry + f[13] * rz) * ry + f[10] * rz * rz;
        w = w + (f[7] - 3.0 * quad * id2) * id3;
    }
    if (order >= 2) {
        v4d lin = f[14] * rx + f[15] * ry + f[16] * rz;
        v4d cub = (f[17] * rx + f[20] * ry + f[21] * rz) * (rx * rx) + (f[18] * ry + f[22] * rx + f[23] * rz) * (ry * ry) +
                  (f[19] * rz + f[24] * rx + f[25] * ry) * (rz * rz) + f[26] * rx * ry * rz;
        w = w + (7.5 * cub * id2 - 1.5 * lin) * id2 * id3;
    }
    return w * INV4PI;
}

/* the lanes set in m, as bits */
INLINE unsigned bits4(v4l m) { return (unsigned)(m[0] & 1) | (unsigned)(m[1] & 2) | (unsigned)(m[2] & 4) | (unsigned)(m[3] & 8); }

/* lane masks by their bits */
static const v4l LANES[16] = {
#define L(b) {-(int64_t)((b) & 1), -(int64_t)((b) >> 1 & 1), -(int64_t)((b) >> 2 & 1), -(int64_t)((b) >> 3 & 1)}
    L(0), L(1), L(2), L(3), L(4), L(5), L(6), L(7), L(8), L(9), L(10), L(11), L(12), L(13), L(14), L(15)
#undef L
};

/* the winding numbers at the points of indices at[0..3] (m of them real, the rest copies
 * of at[0]) into out at the same indices. The lanes whose own walk is at node i are the
 * bits "here". When some lanes open node i and others skip its subtree, the walk goes
 * on into the subtree with the first and keeps (where the subtree ends, all of them) on
 * a stack; the subtrees nest (links_ok), so every lane's walk passes there. */
TARGETS static void winding_4(const Work *w, const int64_t *at, int64_t m)
{
    v4d qx, qy, qz, acc = {0, 0, 0, 0};
    for (int l = 0; l < 4; l++) {
        const double *p = w->points + 3 * at[l < m ? l : 0];
        qx[l] = p[0], qy[l] = p[1], qz[l] = p[2];
    }
    int64_t end[DEPTH];
    unsigned lanes[DEPTH], here = 15;
    int top = 0;
    int64_t i = 0;
    while (i < w->count) {
        const Hot *h = w->hot + i;
        v4d rx = h->c[0] - qx, ry = h->c[1] - qy, rz = h->c[2] - qz;
        v4d d2 = rx * rx + ry * ry + rz * rz;
        unsigned far = bits4(d2 > h->far2) & here, near = here & ~far;
        if (far)
            acc = pick(LANES[far], acc + far_term4(w->nodes + FIELDS * i, rx, ry, rz, d2, w->order), acc);
        if (h->count == 0 && near) { /* (a branch: the processor walks on before the distances are known) */
            if (far)
                end[top] = h->skip, lanes[top] = here, top++, here = near;
            i = i + 1;
        } else {
            int reach = __builtin_popcount(near);
            if (reach && reach * ((h->count + 3) / 4) < h->count) {
                /* few lanes here: each lane's triangles four at a time, added in turn */
                for (unsigned b = near; b; b &= b - 1) {
                    int l = __builtin_ctz(b);
                    double sum = acc[l];
                    for (int64_t k = 0; k < h->count; k += 4) {
                        int left = h->count - k < 4 ? (int)(h->count - k) : 4;
                        v4d term = triangles_term4(w->tri + 9 * (h->first + k), left, qx[l], qy[l], qz[l]);
                        for (int j = 0; j < left; j++)
                            sum = sum + term[j];
                    }
                    acc[l] = sum;
                }
            } else if (reach)
                for (int64_t k = 0; k < h->count; k++)
                    acc = pick(LANES[near], acc + triangle_term4(w->tri + 9 * (h->first + k), qx, qy, qz), acc);
            i = h->skip;
        }
        while (top > 0 && end[top - 1] == i) /* (after an inner node of no subtree too: i + 1 is its end) */
            here = lanes[--top];
    }
    for (int l = 0; l < m; l++)
        w->out[at[l]] = acc[l] != acc[l] ? NAN : acc[l];
}

/* blocks of points taken in turn from the shared counter until none is left (every
 * thread runs the same loop: k and count do not matter) */
static void run(void *arg, int k, int count)
{
    Work *w = arg;
    (void)k, (void)count;
    for (;;) {
        int64_t b = __atomic_fetch_add(&w->next, 1, __ATOMIC_RELAXED);
        int64_t i0 = b * BLOCK, i1 = i0 + BLOCK < w->n ? i0 + BLOCK : w->n;
        if (i0 >= w->n)
            return;
        for (int64_t i = i0; i < i1; i += 4)
            winding_4(w, w->walk + i, i1 - i < 4 ? i1 - i : 4);
    }
}

/* walk (n,): the indices of the points p (n, 3) in the Morton order of their cells in a
 * 1024^3 grid over the box of the finite ones (the others first), so that neighbouring
 * points walk together (any order gives the same sums); 0 when out of memory */
static int walk_order(const double *p, int64_t n, int64_t *walk)
{
    uint64_t *key = malloc(sizeof(uint64_t) * (size_t)(n > 0 ? n : 1));
    if (!key)
        return 0;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY}, scale[3];
    for (int64_t i = 0; i < n; i++) {
        const double *q = p + 3 * i;
        if (isfinite(q[0]) && isfinite(q[1]) && isfinite(q[2]))
            for (int k = 0; k < 3; k++)
                lo[k] = q[k] < lo[k] ? q[k] : lo[k], hi[k] = q[k] > hi[k] ? q[k] : hi[k];
    }
    for (int k = 0; k < 3; k++)
        scale[k] = hi[k] > lo[k] ? 1024.0 / (hi[k] - lo[k]) : 0.0;
    for (int64_t i = 0; i < n; i++) {
        const double *q = p + 3 * i;
        uint64_t c[3];
        for (int k = 0; k < 3; k++) {
            double x = (q[k] - lo[k]) * scale[k];
            c[k] = x >= 1.0 && x <= 1023.0 ? (uint64_t)x : x > 1023.0 ? 1023 : 0; /* (NaN: 0) */
        }
        key[i] = (spread21(c[0]) << 2) | (spread21(c[1]) << 1) | spread21(c[2]);
    }
    int ok = stable_order(key, n, 30, walk);
    free(key);
    return ok;
}

/* the links of a preorder tree: each node's subtree ends after it, within the tree and
 * within every subtree it lies in, at most DEPTH subtrees deep; a leaf's triangles lie
 * within the triangles */
static int links_ok(const int64_t *links, int64_t count, int64_t ntri)
{
    int64_t end[DEPTH]; /* the ends of the subtrees node i lies in, innermost last */
    int depth = 0;
    for (int64_t i = 0; i < count; i++) {
        const int64_t *l = links + 3 * i;
        if (l[0] <= i || l[0] > count || l[1] < 0 || l[1] > ntri || l[2] < 0 || l[2] > ntri - l[1])
            return 0;
        while (depth > 0 && end[depth - 1] <= i)
            depth--;
        if (depth == DEPTH || (depth > 0 && l[0] > end[depth - 1]))
            return 0;
        end[depth++] = l[0];
    }
    return 1;
}

/* get() for an (n, cols) array */
static int get2(PyObject *obj, int type, npy_intp cols, PyArrayObject **out, const char *name)
{
    if (!get(obj, type, -1, out, name))
        return 0;
    if (PyArray_NDIM(*out) != 2 || PyArray_DIM(*out, 1) != cols) {
        PyErr_Format(PyExc_ValueError, "%s: not (n, %d)", name, (int)cols);
        return 0;
    }
    return 1;
}

PyDoc_STRVAR(winding_doc, "winding(points (n, 3) float64, nodes (N, 28) float64, links (N, 3) int64, triangles "
                          "(T, 9) float64, accuracy, order, threads, out (n,) float64): winding numbers into out");

static PyObject *winding(PyObject *self, PyObject *args)
{
    PyObject *op, *on, *ol, *ot, *oo;
    PyArrayObject *pa, *na, *la, *ta, *oa;
    double beta;
    int order, threads;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOdiiO", &op, &on, &ol, &ot, &beta, &order, &threads, &oo) ||
        !get2(op, NPY_FLOAT64, 3, &pa, "points") || !get2(on, NPY_FLOAT64, FIELDS, &na, "nodes") ||
        !get2(ol, NPY_INT64, 3, &la, "links") || !get2(ot, NPY_FLOAT64, 9, &ta, "triangles") ||
        !get(oo, NPY_FLOAT64, PyArray_DIM(pa, 0), &oa, "out"))
        return NULL;
    if (PyArray_DIM(na, 0) != PyArray_DIM(la, 0)) {
        PyErr_SetString(PyExc_ValueError, "nodes and links differ in length");
        return NULL;
    }
    if (order < 0 || order > 2 || threads < 1) {
        PyErr_SetString(PyExc_ValueError, "order is 0, 1 or 2 and threads at least 1");
        return NULL;
    }
    if (!PyArray_ISWRITEABLE(oa)) {
        PyErr_SetString(PyExc_ValueError, "out: not writeable");
        return NULL;
    }
    const double *nodes = PyArray_DATA(na);
    const int64_t *links = PyArray_DATA(la);
    Work w = {PyArray_DATA(pa), nodes, PyArray_DATA(ta), NULL, NULL, PyArray_DIM(pa, 0), PyArray_DIM(na, 0), order,
              PyArray_DATA(oa), 0};
    int ok, memory = 1;
    Py_BEGIN_ALLOW_THREADS
    ok = links_ok(links, w.count, PyArray_DIM(ta, 0));
    Hot *hot = ok ? aligned_alloc(64, sizeof(Hot) * (size_t)(w.count > 0 ? w.count : 1)) : NULL;
    int64_t *walk = ok ? malloc(sizeof(int64_t) * (size_t)(w.n > 0 ? w.n : 1)) : NULL;
    memory = !ok || (hot && walk && walk_order(w.points, w.n, walk));
    if (ok && memory) {
        for (int64_t i = 0; i < w.count; i++) {
            const double *f = nodes + FIELDS * i;
            double t = beta * f[3];
            hot[i] = (Hot){{f[0], f[1], f[2]}, t * t, links[3 * i], links[3 * i + 1], links[3 * i + 2], 0};
        }
        w.hot = hot, w.walk = walk;
        int64_t blocks = (w.n + BLOCK - 1) / BLOCK;
        in_parallel(threads < blocks ? threads : (int)blocks, run, &w);
    }
    free(hot), free(walk);
    Py_END_ALLOW_THREADS
    if (!memory)
        return PyErr_NoMemory();
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "links: a subtree or a leaf's triangles out of range, or subtrees not nested");
        return NULL;
    }
    Py_RETURN_NONE;
}

/* ---- the tree's radii: winding._radii's values ---- */

static inline double norm3(double x, double y, double z) { return sqrt(x * x + y * y + z * z); }

/* np.maximum's: NaN wins */
static inline double most(double m, double x) { return x > m || x != x ? x : m; }

PyDoc_STRVAR(radii_doc, "radii(triangles (T, 9) float64, centre (N, 3) float64, start, end, skip (N,) int64, out (N,) "
                        "float64): winding._radii's radii into out");

static PyObject *radii_py(PyObject *self, PyObject *args)
{
    PyObject *ot, *oc, *os, *oe, *ok, *oo;
    PyArrayObject *ta, *ca, *sa, *ea, *ka, *oa;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOOO", &ot, &oc, &os, &oe, &ok, &oo) || !get2(ot, NPY_FLOAT64, 9, &ta, "triangles") ||
        !get2(oc, NPY_FLOAT64, 3, &ca, "centre") || !get(os, NPY_INT64, PyArray_DIM(ca, 0), &sa, "start") ||
        !get(oe, NPY_INT64, PyArray_DIM(ca, 0), &ea, "end") || !get(ok, NPY_INT64, PyArray_DIM(ca, 0), &ka, "skip") ||
        !get(oo, NPY_FLOAT64, PyArray_DIM(ca, 0), &oa, "out"))
        return NULL;
    if (!PyArray_ISWRITEABLE(oa)) {
        PyErr_SetString(PyExc_ValueError, "out: not writeable");
        return NULL;
    }
    const double *tri = PyArray_DATA(ta), *c = PyArray_DATA(ca);
    const int64_t *start = PyArray_DATA(sa), *end = PyArray_DATA(ea), *skip = PyArray_DATA(ka);
    double *r = PyArray_DATA(oa);
    int64_t n = PyArray_DIM(ca, 0), t = PyArray_DIM(ta, 0);
    for (int64_t k = 0; k < n; k++)
        if (start[k] < 0 || start[k] >= end[k] || end[k] > t) {
            PyErr_SetString(PyExc_ValueError, "start, end: a node's triangles empty or out of range");
            return NULL;
        }
    double *g = malloc(sizeof(double) * 4 * (size_t)(t > 0 ? t : 1)); /* centroid, and the farthest corner from it */
    if (!g)
        return PyErr_NoMemory();
    Py_BEGIN_ALLOW_THREADS
    for (int64_t i = 0; i < t; i++) {
        const double *v = tri + 9 * i;
        double *gi = g + 4 * i;
        for (int a = 0; a < 3; a++)
            gi[a] = (v[a] + v[3 + a] + v[6 + a]) / 3.0;
        gi[3] = norm3(v[0] - gi[0], v[1] - gi[1], v[2] - gi[2]);
        gi[3] = most(gi[3], norm3(v[3] - gi[0], v[4] - gi[1], v[5] - gi[2]));
        gi[3] = most(gi[3], norm3(v[6] - gi[0], v[7] - gi[1], v[8] - gi[2]));
    }
    for (int64_t k = 0; k < n; k++) {
        const double *ck = c + 3 * k;
        double m = 0.0;
        if (skip[k] == k + 1) /* a leaf: its farthest corner */
            for (int64_t i = start[k]; i < end[k]; i++)
                for (int a = 0; a < 3; a++) {
                    const double *v = tri + 9 * i + 3 * a;
                    double x = norm3(v[0] - ck[0], v[1] - ck[1], v[2] - ck[2]);
                    m = i == start[k] && a == 0 ? x : most(m, x);
                }
        else /* its triangles' spheres */
            for (int64_t i = start[k]; i < end[k]; i++) {
                const double *gi = g + 4 * i;
                double x = norm3(gi[0] - ck[0], gi[1] - ck[1], gi[2] - ck[2]) + gi[3];
                m = i == start[k] ? x : most(m, x);
            }
        r[k] = m != m ? NAN : m;
    }
    Py_END_ALLOW_THREADS
    free(g);
    Py_RETURN_NONE;
}

/* ---- the tree's sums: winding._subtree_sums's values ---- */

PyDoc_STRVAR(sums_doc, "subtree_sums(rows (K, T) float64, start (N,) int64, skip (N,) int64, out (N, K) float64): "
                       "winding._subtree_sums's sums into out (a leaf: at most 8 triangles)");

static PyObject *sums_py(PyObject *self, PyObject *args)
{
    PyObject *orow, *os, *ok, *oo;
    PyArrayObject *ra, *sa, *ka, *oa;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOO", &orow, &os, &ok, &oo) || !get(orow, NPY_FLOAT64, -1, &ra, "rows") ||
        !get(os, NPY_INT64, -1, &sa, "start") || !get(ok, NPY_INT64, PyArray_SIZE(sa), &ka, "skip"))
        return NULL;
    if (PyArray_NDIM(ra) != 2) {
        PyErr_SetString(PyExc_ValueError, "rows: not (K, T)");
        return NULL;
    }
    int64_t K = PyArray_DIM(ra, 0), T = PyArray_DIM(ra, 1), n = PyArray_SIZE(sa);
    if (!get2(oo, NPY_FLOAT64, K, &oa, "out"))
        return NULL;
    if (PyArray_DIM(oa, 0) != n || !PyArray_ISWRITEABLE(oa)) {
        PyErr_SetString(PyExc_ValueError, "out: not (N, K) or not writeable");
        return NULL;
    }
    const double *rows = PyArray_DATA(ra);
    const int64_t *start = PyArray_DATA(sa), *skip = PyArray_DATA(ka);
    double *out = PyArray_DATA(oa);
    /* the leaves' triangles as np.add.reduceat(rows, start[leaf], axis=1) takes them: from
     * a leaf's start to the next leaf's (the last: to T) */
    int64_t last = -1; /* the leaf before, or -1 */
    for (int64_t k = 0; k <= n; k++) {
        if (k < n && skip[k] != k + 1) {
            if (k + 1 >= n || skip[k + 1] < 0 || skip[k + 1] >= n) {
                PyErr_SetString(PyExc_ValueError, "skip: an inner node's children out of range");
                return NULL;
            }
            continue;
        }
        if (k < n && (start[k] < 0 || start[k] >= T)) {
            PyErr_SetString(PyExc_ValueError, "start: out of range");
            return NULL;
        }
        if (last >= 0) {
            int64_t to = k < n ? start[k] : T, size = to > start[last] ? to - start[last] : 1;
            if (size > 8) {
                PyErr_SetString(PyExc_ValueError, "start: a leaf of more than 8 triangles");
                return NULL;
            }
        }
        last = k;
    }
    Py_BEGIN_ALLOW_THREADS
    last = -1;
    for (int64_t k = 0; k <= n; k++) {
        if (k < n && skip[k] != k + 1)
            continue;
        if (last >= 0) {
            int64_t s = start[last], to = k < n ? start[k] : T, e = to > s ? to : s + 1;
            for (int64_t q = 0; q < K; q++) {
                const double *r = rows + q * T;
                double x = r[s];
                if (e - s > 1) { /* the first, plus the sum of the others (numpy's pairwise sum below 8 terms) */
                    double rest = r[s + 1];
                    for (int64_t t = s + 2; t < e; t++)
                        rest = rest + r[t];
                    x = x + rest;
                }
                out[last * K + q] = x;
            }
        }
        last = k;
    }
    for (int64_t k = n - 1; k >= 0; k--) /* (children after their parent) */
        if (skip[k] != k + 1)
            for (int64_t q = 0; q < K; q++)
                out[k * K + q] = out[(k + 1) * K + q] + out[skip[k + 1] * K + q];
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

/* ---- the triangles' moments: the rows winding._node_fields sums ---- */

static const int PAIRS[6][2] = {{0, 0}, {1, 1}, {2, 2}, {0, 1}, {0, 2}, {1, 2}};

PyDoc_STRVAR(moments_doc, "moments(triangles (T, 9) float64, an (T, 3) float64, centroid (T, 3) float64, origin (3,) "
                          "float64, out (34, T) float64): winding._node_fields's rows of per-triangle moments into out");

static PyObject *moments_py(PyObject *self, PyObject *args)
{
    PyObject *ot, *oa, *oc, *og, *oo;
    PyArrayObject *ta, *aa, *ca, *ga, *outa;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOOOO", &ot, &oa, &oc, &og, &oo) || !get2(ot, NPY_FLOAT64, 9, &ta, "triangles") ||
        !get2(oa, NPY_FLOAT64, 3, &aa, "an") || !get2(oc, NPY_FLOAT64, 3, &ca, "centroid") ||
        !get(og, NPY_FLOAT64, 3, &ga, "origin") || !get(oo, NPY_FLOAT64, 34 * PyArray_DIM(ta, 0), &outa, "out"))
        return NULL;
    int64_t t = PyArray_DIM(ta, 0);
    if (PyArray_DIM(aa, 0) != t || PyArray_DIM(ca, 0) != t || !PyArray_ISWRITEABLE(outa)) {
        PyErr_SetString(PyExc_ValueError, "an, centroid: not one row a triangle, or out not writeable");
        return NULL;
    }
    const double *tri = PyArray_DATA(ta), *an = PyArray_DATA(aa), *cen = PyArray_DATA(ca), *o = PyArray_DATA(ga);
    double *out = PyArray_DATA(outa);
    Py_BEGIN_ALLOW_THREADS
    for (int64_t i = 0; i < t; i++) {
        const double *a = an + 3 * i, *g = cen + 3 * i, *v = tri + 9 * i;
        double p[3], u[3][3];
        for (int j = 0; j < 3; j++) {
            p[j] = g[j] - o[j];
            for (int c = 0; c < 3; c++)
                u[c][j] = v[3 * c + j] - g[j];
        }
        double r0 = sqrt(a[0] * a[0] + a[1] * a[1] + a[2] * a[2]);
        out[i] = r0;
        for (int j = 0; j < 3; j++) {
            out[(1 + j) * t + i] = r0 * p[j];
            out[(4 + j) * t + i] = a[j];
            for (int k = 0; k < 3; k++)
                out[(7 + 3 * j + k) * t + i] = a[j] * p[k];
        }
        for (int k = 0; k < 6; k++) { /* E[(x - o)_a (x - o)_b] over the triangle, times an */
            int x = PAIRS[k][0], y = PAIRS[k][1];
            double second = p[x] * p[y] + (u[0][x] * u[0][y] + u[1][x] * u[1][y] + u[2][x] * u[2][y]) / 12.0;
            for (int j = 0; j < 3; j++)
                out[(16 + k + 6 * j) * t + i] = a[j] * second;
        }
    }
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

/* ---- the nodes' expansions: winding._expansions's values ---- */

PyDoc_STRVAR(expansions_doc, "expansions(sums (N, 34) float64, origin (3,) float64, out (N, 28) float64): "
                             "winding._expansions's fields into out (its radius column left as it is)");

static PyObject *expansions_py(PyObject *self, PyObject *args)
{
    PyObject *os, *og, *oo;
    PyArrayObject *sa, *ga, *outa;
    (void)self;
    if (!PyArg_ParseTuple(args, "OOO", &os, &og, &oo) || !get2(os, NPY_FLOAT64, 34, &sa, "sums") ||
        !get(og, NPY_FLOAT64, 3, &ga, "origin") || !get2(oo, NPY_FLOAT64, FIELDS, &outa, "out"))
        return NULL;
    int64_t n = PyArray_DIM(sa, 0);
    if (PyArray_DIM(outa, 0) != n || !PyArray_ISWRITEABLE(outa)) {
        PyErr_SetString(PyExc_ValueError, "out: not one row a node, or not writeable");
        return NULL;
    }
    const double *sums = PyArray_DATA(sa), *o = PyArray_DATA(ga);
    double *out = PyArray_DATA(outa);
    int pair[3][3]; /* the index in PAIRS of (j, l) or (l, j) */
    for (int k = 0; k < 6; k++)
        pair[PAIRS[k][0]][PAIRS[k][1]] = pair[PAIRS[k][1]][PAIRS[k][0]] = k;
    Py_BEGIN_ALLOW_THREADS
    for (int64_t i = 0; i < n; i++) {
        const double *S = sums + 34 * i;
        double *f = out + FIELDS * i, c[3], m[3][3], s[3][6];
        for (int j = 0; j < 3; j++)
            c[j] = S[1 + j] / S[0];
        for (int a = 0; a < 3; a++)
            for (int j = 0; j < 3; j++)
                m[a][j] = S[7 + 3 * a + j] - S[4 + a] * c[j];
        for (int k = 0; k < 6; k++) { /* s[a][k]: the sum of an_a (x - c)_j (x - c)_l, (j, l) = PAIRS[k] */
            int j = PAIRS[k][0], l = PAIRS[k][1];
            for (int a = 0; a < 3; a++)
                s[a][k] = S[16 + 6 * a + k] - S[7 + 3 * a + j] * c[l] - S[7 + 3 * a + l] * c[j] + S[4 + a] * c[j] * c[l];
        }
#define T3(a, j, l) s[a][pair[j][l]]
        for (int j = 0; j < 3; j++)
            f[j] = c[j] + o[j], f[4 + j] = S[4 + j];
        f[7] = m[0][0] + m[1][1] + m[2][2];
        f[8] = m[0][0], f[9] = m[1][1], f[10] = m[2][2];
        f[11] = m[0][1] + m[1][0], f[12] = m[0][2] + m[2][0], f[13] = m[1][2] + m[2][1];
        for (int k = 0; k < 3; k++)
            f[14 + k] = 2.0 * (T3(0, 0, k) + T3(1, 1, k) + T3(2, 2, k)) + T3(k, 0, 0) + T3(k, 1, 1) + T3(k, 2, 2);
        f[17] = T3(0, 0, 0), f[18] = T3(1, 1, 1), f[19] = T3(2, 2, 2);
        f[20] = 2 * T3(0, 0, 1) + T3(1, 0, 0), f[21] = 2 * T3(0, 0, 2) + T3(2, 0, 0);
        f[22] = 2 * T3(1, 1, 0) + T3(0, 1, 1), f[23] = 2 * T3(1, 1, 2) + T3(2, 1, 1);
        f[24] = 2 * T3(2, 2, 0) + T3(0, 2, 2), f[25] = 2 * T3(2, 2, 1) + T3(1, 2, 2);
        f[26] = 2 * (T3(0, 1, 2) + T3(1, 0, 2) + T3(2, 0, 1));
#undef T3
        for (int k = 27; k < FIELDS; k++)
            f[k] = 0.0;
    }
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

PyDoc_STRVAR(morton_doc, "morton(points (n, 3) float64) -> (n,) uint64: winding._morton's codes.");

static PyObject *morton_py(PyObject *self, PyObject *args)
{
    PyObject *op;
    PyArrayObject *pa;
    (void)self;
    if (!PyArg_ParseTuple(args, "O", &op) || !get2(op, NPY_FLOAT64, 3, &pa, "points"))
        return NULL;
    npy_intp n = PyArray_DIM(pa, 0);
    PyArrayObject *out = (PyArrayObject *)PyArray_SimpleNew(1, (npy_intp[]){n}, NPY_UINT64);
    if (!out)
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    morton21(PyArray_DATA(pa), n, PyArray_DATA(out));
    Py_END_ALLOW_THREADS
    return (PyObject *)out;
}

PyDoc_STRVAR(order_doc, "order(codes (n,) uint64) -> (n,) int64: np.argsort(codes, kind=\"stable\") (codes below 2^63).");

static PyObject *order_py(PyObject *self, PyObject *args)
{
    PyObject *oc;
    PyArrayObject *ca;
    (void)self;
    if (!PyArg_ParseTuple(args, "O", &oc) || !get(oc, NPY_UINT64, -1, &ca, "codes"))
        return NULL;
    npy_intp n = PyArray_SIZE(ca);
    const uint64_t *c = PyArray_DATA(ca);
    for (npy_intp i = 0; i < n; i++)
        if (c[i] >> 63) {
            PyErr_SetString(PyExc_ValueError, "codes: not below 2^63");
            return NULL;
        }
    PyArrayObject *out = (PyArrayObject *)PyArray_SimpleNew(1, (npy_intp[]){n}, NPY_INT64);
    if (!out)
        return NULL;
    int ok;
    Py_BEGIN_ALLOW_THREADS
    ok = stable_order(c, n, 63, PyArray_DATA(out));
    Py_END_ALLOW_THREADS
    if (!ok) {
        Py_DECREF(out);
        return PyErr_NoMemory();
    }
    return (PyObject *)out;
}

PyDoc_STRVAR(faces_doc, "faces(triangles (T, 9) float64) -> (area normals (T, 3), centroids (T, 3)) float64: "
                        "winding._area_normals and the centroids (a + b + c) / 3.");

static PyObject *faces_py(PyObject *self, PyObject *args)
{
    PyObject *ot;
    PyArrayObject *ta;
    (void)self;
    if (!PyArg_ParseTuple(args, "O", &ot) || !get2(ot, NPY_FLOAT64, 9, &ta, "triangles"))
        return NULL;
    npy_intp n = PyArray_DIM(ta, 0), dims[2] = {n, 3};
    PyArrayObject *an = (PyArrayObject *)PyArray_SimpleNew(2, dims, NPY_FLOAT64);
    PyArrayObject *g = (PyArrayObject *)PyArray_SimpleNew(2, dims, NPY_FLOAT64);
    if (!an || !g) {
        Py_XDECREF(an), Py_XDECREF(g);
        return NULL;
    }
    const double *tri = PyArray_DATA(ta);
    double *a = PyArray_DATA(an), *c = PyArray_DATA(g);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp t = 0; t < n; t++) {
        const double *f = tri + 9 * t;
        double u[3], v[3];
        for (int k = 0; k < 3; k++)
            u[k] = f[3 + k] - f[k], v[k] = f[6 + k] - f[k];
        for (int k = 0; k < 3; k++) {
            int i = (k + 1) % 3, j = (k + 2) % 3;
            a[3 * t + k] = 0.5 * (u[i] * v[j] - u[j] * v[i]);
            c[3 * t + k] = (f[k] + f[3 + k] + f[6 + k]) / 3.0;
        }
    }
    Py_END_ALLOW_THREADS
    PyObject *out = PyTuple_Pack(2, an, g);
    Py_DECREF(an), Py_DECREF(g);
    return out;
}

PyDoc_STRVAR(layout_doc, "layout(codes (T,) uint64 in order, leaf) -> (start, end, skip) (N,) int64 each: "
                         "winding._layout's nodes, in preorder.");

/* the highest set bit of x > 0 */
static inline int top_bit(uint64_t x) { return 63 - __builtin_clzll(x); }

/* the first index in c[s .. e-1] (in order) whose code is at least key, e if none */
static int64_t first_at_least(const uint64_t *c, int64_t s, int64_t e, uint64_t key)
{
    while (s < e) {
        int64_t m = s + (e - s) / 2;
        if (c[m] < key)
            s = m + 1;
        else
            e = m;
    }
    return s;
}

static PyObject *layout_py(PyObject *self, PyObject *args)
{
    PyObject *oc;
    PyArrayObject *ca;
    long long leaf;
    (void)self;
    if (!PyArg_ParseTuple(args, "OL", &oc, &leaf) || !get(oc, NPY_UINT64, -1, &ca, "codes"))
        return NULL;
    npy_intp n = PyArray_SIZE(ca);
    const uint64_t *c = PyArray_DATA(ca);
    if (leaf < 1 || PyArray_NDIM(ca) != 1) {
        PyErr_SetString(PyExc_ValueError, "layout: codes (T,) and leaf >= 1");
        return NULL;
    }
    for (npy_intp i = 1; i < n; i++)
        if (c[i] < c[i - 1]) {
            PyErr_SetString(PyExc_ValueError, "layout: codes not in order");
            return NULL;
        }
    npy_intp most = n > 0 ? 2 * n - 1 : 0; /* nodes: every inner node splits its triangles in two */
    int64_t *start = malloc(sizeof(int64_t) * (size_t)(most + 1)), *end = malloc(sizeof(int64_t) * (size_t)(most + 1)),
            *skip = malloc(sizeof(int64_t) * (size_t)(most + 1));
    /* pending work: a range to visit (id -1) or a node whose subtree is done (its id); a
     * split either drops the top differing bit (63 at most) or halves equal codes (63 at
     * most), two entries a level */
    enum { STACK = 4 * 130 };
    int64_t stack_s[STACK], stack_e[STACK], stack_id[STACK];
    int64_t count = 0;
    int top = 0;
    if (!start || !end || !skip) {
        free(start), free(end), free(skip);
        return PyErr_NoMemory();
    }
    Py_BEGIN_ALLOW_THREADS
    if (n > 0)
        stack_s[0] = 0, stack_e[0] = n, stack_id[0] = -1, top = 1;
    while (top > 0) {
        top--;
        if (stack_id[top] >= 0) {
            skip[stack_id[top]] = count;
            continue;
        }
        int64_t s = stack_s[top], e = stack_e[top], id = count++;
        start[id] = s, end[id] = e;
        if (e - s <= leaf) {
            skip[id] = id + 1;
            continue;
        }
        uint64_t first = c[s], last = c[e - 1], diff = first ^ last;
        int64_t m = diff == 0 ? (s + e) / 2 : first_at_least(c, s, e, (last >> top_bit(diff)) << top_bit(diff));
        stack_id[top] = id, top++;                                       /* then its subtree is done */
        stack_s[top] = m, stack_e[top] = e, stack_id[top] = -1, top++;   /* then the right child */
        stack_s[top] = s, stack_e[top] = m, stack_id[top] = -1, top++;   /* first the left child */
    }
    Py_END_ALLOW_THREADS
    PyObject *out = NULL;
    PyArrayObject *a[3] = {NULL, NULL, NULL};
    int64_t *from[3] = {start, end, skip};
    for (int k = 0; k < 3; k++) {
        a[k] = (PyArrayObject *)PyArray_SimpleNew(1, (npy_intp[]){count}, NPY_INT64);
        if (!a[k])
            break;
        memcpy(PyArray_DATA(a[k]), from[k], sizeof(int64_t) * (size_t)count);
    }
    if (a[0] && a[1] && a[2])
        out = PyTuple_Pack(3, a[0], a[1], a[2]);
    for (int k = 0; k < 3; k++)
        Py_XDECREF(a[k]);
    free(start), free(end), free(skip);
    return out;
}

static PyMethodDef methods[] = {
    {"winding", winding, METH_VARARGS, winding_doc},
    {"morton", morton_py, METH_VARARGS, morton_doc},
    {"radii", radii_py, METH_VARARGS, radii_doc},
    {"subtree_sums", sums_py, METH_VARARGS, sums_doc},
    {"moments", moments_py, METH_VARARGS, moments_doc},
    {"expansions", expansions_py, METH_VARARGS, expansions_doc},
    {"order", order_py, METH_VARARGS, order_doc},
    {"layout", layout_py, METH_VARARGS, layout_doc},
    {"faces", faces_py, METH_VARARGS, faces_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_cwinding", "Compiled winding numbers (see winding.py).", -1,
                                    methods};

PyMODINIT_FUNC PyInit__cwinding(void)
{
    import_array();
    PyObject *m = PyModule_Create(&module);
    if (m && PyModule_AddIntConstant(m, "FIELDS", FIELDS) < 0) {
        Py_DECREF(m);
        return NULL;
    }
    return m;
}
