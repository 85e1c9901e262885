/* Compiled volume queries over a triangle tree (distance.TriangleTree): the same bytes as
 * the NumPy code in distance.py and parity.py.
 *
 * closest(): for each point, the face whose computed squared distance is the least (ties:
 * the lowest face index) and the closest point on it (Ericson's regions, distance.py's
 * _closest_on). A node is skipped only when its box is farther than the best distance so
 * far plus ``tol`` (which exceeds every rounding error of the distances), so the answer is
 * the minimum over all faces, whatever the tree or the order of the visit.
 * crossings(): for each point and ray, the parity of the faces the ray crosses (the
 * watertight test of Woop, Benthin and Wald 2013, ties on an edge broken by the edge's
 * direction so that a crossing at a shared edge or vertex counts once), and whether most
 * rays have an odd count. Boxes are grown by ``tol`` for the rays.
 *
 * Every float64 operation is the NumPy code's, in its order (built with -ffp-contract=off).
 * The points are split between threads in fixed ranges; the GIL is released meanwhile.
 * Arrays are checked: a wrong shape, a non-finite value or an index out of range raises.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include "_ckernel.h"
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <pthread.h>

#define MAX_THREADS 8
/* below this many points a call runs on one thread */
#define THREAD_POINTS 512
#define MAX_DEPTH 62

typedef struct {
    void (*fn)(void *ctx, int k, int count);
    void *ctx;
    int k, count;
} Job;

static void *run_job(void *arg)
{
    Job *j = arg;
    j->fn(j->ctx, j->k, j->count);
    return NULL;
}

/* fn(ctx, k, count) for k = 0 .. count - 1, on count threads (k = 0 on the caller; a share
 * whose thread does not start runs on the caller) */
static void in_parallel(int count, void (*fn)(void *, int, int), void *ctx)
{
    count = count < 1 ? 1 : count > MAX_THREADS ? MAX_THREADS : count;
    Job job[MAX_THREADS];
    pthread_t id[MAX_THREADS];
    int started[MAX_THREADS] = {0};
    for (int k = 0; k < count; k++)
        job[k] = (Job){fn, ctx, k, count};
    for (int k = 1; k < count; k++)
        started[k] = pthread_create(&id[k], NULL, run_job, &job[k]) == 0;
    fn(ctx, 0, count);
    for (int k = 1; k < count; k++)
        if (started[k])
            pthread_join(id[k], NULL);
        else
            fn(ctx, k, count);
}

static inline void share(int64_t n, int k, int count, int64_t *i0, int64_t *i1)
{
    *i0 = n * k / count, *i1 = n * (k + 1) / count;
}

/* ---- the tree ---- */

typedef struct {
    const double *tri;    /* (F, 9): the triangles in tree order */
    const int64_t *order; /* (F,): each one's face index */
    const uint8_t *thin;  /* (F,): whether it is thin (distance.thin_faces) */
    const double *lo, *hi; /* (2 L - 1, 3): node boxes, heap order (children of i: 2i+1, 2i+2) */
    int64_t nf, leaves, leaf; /* leaf j (node L - 1 + j) holds slots j*leaf .. */
} Tree;

static int finite_all(const double *x, npy_intp n)
{
    for (npy_intp i = 0; i < n; i++)
        if (!isfinite(x[i]))
            return 0;
    return 1;
}

/* the tree's arrays checked into *t; 0 with an exception set when wrong */
static int get_tree(PyObject *otri, PyObject *oorder, PyObject *othin, PyObject *olo, PyObject *ohi, long long leaf,
                    Tree *t)
{
    PyArrayObject *tri, *order, *thin, *lo, *hi;
    if (!get(otri, NPY_FLOAT64, -1, &tri, "triangles") || !get(oorder, NPY_INT64, -1, &order, "order") ||
        !get(othin, NPY_UINT8, PyArray_SIZE((PyArrayObject *)oorder), &thin, "thin") ||
        !get(olo, NPY_FLOAT64, -1, &lo, "lo") || !get(ohi, NPY_FLOAT64, -1, &hi, "hi"))
        return 0;
    npy_intp nf = PyArray_SIZE(order), nodes = PyArray_SIZE(lo) / 3;
    if (PyArray_SIZE(tri) != 9 * nf || nf < 1 || PyArray_NDIM(lo) != 2 || PyArray_DIM(lo, 1) != 3 ||
        PyArray_SIZE(hi) != PyArray_SIZE(lo) || leaf < 1 || leaf > 64) {
        PyErr_SetString(PyExc_ValueError, "tree: inconsistent shapes");
        return 0;
    }
    int64_t leaves = (nodes + 1) / 2;
    if (nodes < 1 || (leaves & (leaves - 1)) != 0 || 2 * leaves - 1 != nodes || leaves > ((int64_t)1 << MAX_DEPTH) ||
        leaves * leaf < nf || (leaves > 1 && leaves / 2 * leaf >= nf)) {
        PyErr_SetString(PyExc_ValueError, "tree: node count does not fit the faces");
        return 0;
    }
    const int64_t *o = PyArray_DATA(order);
    for (npy_intp i = 0; i < nf; i++)
        if (o[i] < 0 || o[i] >= nf) {
            PyErr_SetString(PyExc_ValueError, "tree: face index out of range");
            return 0;
        }
    if (!finite_all(PyArray_DATA(tri), 9 * nf)) {
        PyErr_SetString(PyExc_ValueError, "tree: non-finite coordinate");
        return 0;
    }
    const double *l = PyArray_DATA(lo), *h = PyArray_DATA(hi);
    for (npy_intp i = 0; i < 3 * nodes; i++)
        if (isnan(l[i]) || isnan(h[i])) {
            PyErr_SetString(PyExc_ValueError, "tree: NaN in a box");
            return 0;
        }
    *t = (Tree){PyArray_DATA(tri), o, PyArray_DATA(thin), l, h, nf, leaves, leaf};
    return 1;
}

static int get_points(PyObject *obj, PyArrayObject **out, npy_intp *n)
{
    if (!get(obj, NPY_FLOAT64, -1, out, "points"))
        return 0;
    if (PyArray_NDIM(*out) != 2 || PyArray_DIM(*out, 1) != 3) {
        PyErr_SetString(PyExc_ValueError, "points: not (n, 3)");
        return 0;
    }
    *n = PyArray_DIM(*out, 0);
    if (!finite_all(PyArray_DATA(*out), 3 * *n)) {
        PyErr_SetString(PyExc_ValueError, "points: non-finite coordinate");
        return 0;
    }
    return 1;
}

/* ---- closest points ---- */

static inline double dot(const double *u, const double *v) { return u[0] * v[0] + u[1] * v[1] + u[2] * v[2]; }

/* q = a + s * u */
static inline void along(const double *a, double s, const double *u, double *q)
{
    for (int k = 0; k < 3; k++)
        q[k] = a[k] + s * u[k];
}

/* the closest point of segment a + s u (s in [0, 1]) to p; its squared distance */
static inline double segment(const double *a, const double *u, const double *p, double *q)
{
    double ap[3] = {p[0] - a[0], p[1] - a[1], p[2] - a[2]};
    double uu = dot(u, u), s = uu > 0 ? dot(ap, u) / uu : 0.0;
    s = s < 0 ? 0.0 : s > 1 ? 1.0 : s;
    along(a, s, u, q);
    double d[3] = {p[0] - q[0], p[1] - q[1], p[2] - q[2]};
    return dot(d, d);
}

/* The closest point q of triangle t (9 doubles) to p, by Ericson's regions (Real-Time
 * Collision Detection 5.1.5); when rounding puts p in no region, the closest of the three
 * edges; for a thin triangle (whose regions rounding may confuse), the closest of the
 * region's point and the three edges' (ties: in that order). Returns |p - q|^2, +inf
 * instead of NaN. */
static inline void copy3(const double *a, double *q) { q[0] = a[0], q[1] = a[1], q[2] = a[2]; }

/* Ericson's closest point, each quantity computed when first needed */
static void regions(const double *a, const double *b, const double *c, const double *ab, const double *ac,
                    const double *p, double *q)
{
    double ap[3], bp[3], cp[3], bc[3];
    for (int k = 0; k < 3; k++)
        ap[k] = p[k] - a[k];
    double d1 = dot(ab, ap), d2 = dot(ac, ap);
    if (d1 <= 0 && d2 <= 0)
        return copy3(a, q);
    for (int k = 0; k < 3; k++)
        bp[k] = p[k] - b[k];
    double d3 = dot(ab, bp), d4 = dot(ac, bp);
    if (d3 >= 0 && d4 <= d3)
        return copy3(b, q);
    double vc = d1 * d4 - d3 * d2;
    if (vc <= 0 && d1 >= 0 && d3 <= 0) {
        double den = d1 - d3;
        return along(a, den != 0 ? d1 / den : 0.0, ab, q);
    }
    for (int k = 0; k < 3; k++)
        cp[k] = p[k] - c[k];
    double d5 = dot(ab, cp), d6 = dot(ac, cp);
    if (d6 >= 0 && d5 <= d6)
        return copy3(c, q);
    double vb = d5 * d2 - d1 * d6;
    if (vb <= 0 && d2 >= 0 && d6 <= 0) {
        double den = d2 - d6;
        return along(a, den != 0 ? d2 / den : 0.0, ac, q);
    }
    for (int k = 0; k < 3; k++)
        bc[k] = c[k] - b[k];
    double va = d3 * d6 - d5 * d4;
    if (va <= 0 && d4 - d3 >= 0 && d5 - d6 >= 0) {
        double e = d4 - d3, den = e + (d5 - d6);
        return along(b, den != 0 ? e / den : 0.0, bc, q);
    }
    if (va >= 0 && vb >= 0 && vc >= 0 && va + vb + vc > 0) {
        double den = va + vb + vc, v = vb / den, w = vc / den;
        for (int k = 0; k < 3; k++)
            q[k] = a[k] + ab[k] * v + ac[k] * w;
        return;
    }
    double r[3], s[3];
    double best = segment(a, ab, p, q), d = segment(b, bc, p, r), e = segment(a, ac, p, s);
    if (d < best)
        best = d, copy3(r, q);
    if (e < best)
        copy3(s, q);
}

static double closest_on(const double *t, int thin, const double *p, double *q)
{
    const double *a = t, *b = t + 3, *c = t + 6;
    double ab[3], ac[3], bc[3];
    for (int k = 0; k < 3; k++)
        ab[k] = b[k] - a[k], ac[k] = c[k] - a[k], bc[k] = c[k] - b[k];
    regions(a, b, c, ab, ac, p, q);
    double d[3] = {p[0] - q[0], p[1] - q[1], p[2] - q[2]};
    double dd = dot(d, d);
    if (thin) {
        const double *start[3] = {a, b, a}, *dir[3] = {ab, bc, ac};
        double r[3];
        for (int e = 0; e < 3; e++) {
            double de = segment(start[e], dir[e], p, r);
            if (de < dd)
                dd = de, q[0] = r[0], q[1] = r[1], q[2] = r[2];
        }
    }
    return isnan(dd) ? INFINITY : dd;
}

/* squared distance from p to the box of triangle t: no more than its distance */
static inline double face_d2(const double *t, const double *p)
{
    double s = 0;
    for (int k = 0; k < 3; k++) {
        double lo = t[k] < t[3 + k] ? t[k] : t[3 + k], hi = t[k] < t[3 + k] ? t[3 + k] : t[k];
        lo = t[6 + k] < lo ? t[6 + k] : lo, hi = t[6 + k] > hi ? t[6 + k] : hi;
        double g = lo - p[k] > p[k] - hi ? lo - p[k] : p[k] - hi;
        g = g > 0 ? g : 0.0;
        s += g * g;
    }
    return s;
}

/* squared distance from p to box i (+inf for an empty box) */
static inline double box_d2(const Tree *t, int64_t i, const double *p)
{
    double s = 0;
    for (int k = 0; k < 3; k++) {
        double lo = t->lo[3 * i + k] - p[k], hi = p[k] - t->hi[3 * i + k];
        double g = lo > hi ? lo : hi;
        g = g > 0 ? g : 0.0;
        s += g * g;
    }
    return s;
}

#ifdef COUNT
static int64_t faces_tested, nodes_opened;
#endif

typedef struct {
    Tree t;
    const double *points;
    const int64_t *visit; /* the points in this order (near ones in turn) */
    double tol;
    double *dist, *closest;
    int64_t *face;
    int64_t n;
} Closest;

/* the closest face of p; *slot: on entry a slot whose face starts the search (or -1),
 * on return the slot of the answer */
static void closest_one(const Tree *t, const double *p, double tol, double *dist, double *cq, int64_t *face,
                        int64_t *slot)
{
    double best = INFINITY, bound = INFINITY, q[3], bq[3] = {NAN, NAN, NAN};
    int64_t bestf = INT64_MAX, bests = -1, stack[2 * MAX_DEPTH + 4];
    double sd[2 * MAX_DEPTH + 4];
    if (*slot >= 0) {
        best = closest_on(t->tri + 9 * *slot, t->thin[*slot], p, bq), bestf = t->order[*slot], bests = *slot;
        double r = sqrt(best) + tol;
        bound = r * r;
    }
    int top = 0;
    stack[0] = 0, sd[0] = box_d2(t, 0, p), top = 1;
    while (top) {
        top--;
        int64_t node = stack[top];
        if (sd[top] > bound)
            continue;
        if (node >= t->leaves - 1) {
            int64_t s0 = (node - (t->leaves - 1)) * t->leaf, s1 = s0 + t->leaf;
            s1 = s1 < t->nf ? s1 : t->nf;
            for (int64_t s = s0; s < s1; s++) {
                if (face_d2(t->tri + 9 * s, p) > bound)
                    continue;
#ifdef COUNT
                __atomic_fetch_add(&faces_tested, 1, __ATOMIC_RELAXED);
#endif
                double d2 = closest_on(t->tri + 9 * s, t->thin[s], p, q);
                int64_t f = t->order[s];
                if (d2 < best || (d2 == best && f < bestf)) {
                    best = d2, bestf = f, bests = s, bq[0] = q[0], bq[1] = q[1], bq[2] = q[2];
                    double r = sqrt(best) + tol;
                    bound = r * r;
                }
            }
            continue;
        }
        int64_t l = 2 * node + 1, r = l + 1;
#ifdef COUNT
        __atomic_fetch_add(&nodes_opened, 1, __ATOMIC_RELAXED);
#endif
        double dl = box_d2(t, l, p), dr = box_d2(t, r, p);
        /* the nearer child on top */
        if (dl <= dr) {
            if (dr <= bound)
                stack[top] = r, sd[top++] = dr;
            if (dl <= bound)
                stack[top] = l, sd[top++] = dl;
        } else {
            if (dl <= bound)
                stack[top] = l, sd[top++] = dl;
            if (dr <= bound)
                stack[top] = r, sd[top++] = dr;
        }
    }
    *dist = sqrt(best), *face = bestf, *slot = bests;
    cq[0] = bq[0], cq[1] = bq[1], cq[2] = bq[2];
}

static void closest_job(void *ctx, int k, int count)
{
    Closest *c = ctx;
    int64_t i0, i1, slot = -1;
    share(c->n, k, count, &i0, &i1);
    for (int64_t j = i0; j < i1; j++) {
        int64_t i = c->visit[j];
        closest_one(&c->t, c->points + 3 * i, c->tol, c->dist + i, c->closest + 3 * i, c->face + i, &slot);
    }
}

/* whether visit (n,) is a permutation of 0 .. n - 1 */
static int get_visit(PyObject *obj, npy_intp n, PyArrayObject **out)
{
    if (!get(obj, NPY_INT64, n, out, "visit"))
        return 0;
    const int64_t *v = PyArray_DATA(*out);
    uint8_t *seen = calloc((size_t)n + 1, 1);
    if (!seen) {
        PyErr_NoMemory();
        return 0;
    }
    int ok = 1;
    for (npy_intp i = 0; i < n && ok; i++)
        if (v[i] < 0 || v[i] >= n || seen[v[i]]++)
            ok = 0;
    free(seen);
    if (!ok)
        PyErr_SetString(PyExc_ValueError, "visit: not a permutation of the points");
    return ok;
}

static int get_out(PyObject *obj, int type, npy_intp size, PyArrayObject **out, const char *name)
{
    if (!get(obj, type, size, out, name))
        return 0;
    if (!PyArray_ISWRITEABLE(*out)) {
        PyErr_Format(PyExc_ValueError, "%s: not writeable", name);
        return 0;
    }
    return 1;
}

PyDoc_STRVAR(closest_doc, "closest(triangles (F,9) f8, order (F,) i8, thin (F,) u1, lo (N,3) f8, hi (N,3) f8, leaf, points (n,3) f8, "
                          "visit (n,) i8, tol, distance (n,) f8, closest (n,3) f8, face (n,) i8, threads): distance._closest_numpy "
                          "into the three output arrays.");

static PyObject *closest(PyObject *self, PyObject *args)
{
    PyObject *otri, *oorder, *othin, *olo, *ohi, *opts, *ovisit, *odist, *oclosest, *oface;
    long long leaf;
    double tol;
    int threads;
    Tree t;
    PyArrayObject *pts, *visit, *dist, *cl, *face;
    npy_intp n;
    if (!PyArg_ParseTuple(args, "OOOOOLOOdOOOi", &otri, &oorder, &othin, &olo, &ohi, &leaf, &opts, &ovisit, &tol,
                          &odist, &oclosest, &oface, &threads) ||
        !get_tree(otri, oorder, othin, olo, ohi, leaf, &t) || !get_points(opts, &pts, &n) || !get_visit(ovisit, n, &visit) ||
        !get_out(odist, NPY_FLOAT64, n, &dist, "distance") || !get_out(oclosest, NPY_FLOAT64, 3 * n, &cl, "closest") ||
        !get_out(oface, NPY_INT64, n, &face, "face"))
        return NULL;
    if (!(tol >= 0 && isfinite(tol))) {
        PyErr_SetString(PyExc_ValueError, "closest: tol must be finite and >= 0");
        return NULL;
    }
    Closest c = {t, PyArray_DATA(pts), PyArray_DATA(visit), tol, PyArray_DATA(dist), PyArray_DATA(cl), PyArray_DATA(face), n};
    int count = n < THREAD_POINTS ? 1 : threads;
    Py_BEGIN_ALLOW_THREADS
    in_parallel(count, closest_job, &c);
    Py_END_ALLOW_THREADS
#ifdef COUNT
    fprintf(stderr, "faces tested %g nodes opened %g per point\n", (double)faces_tested / n, (double)nodes_opened / n);
    faces_tested = nodes_opened = 0;
#endif
    Py_RETURN_NONE;
}

/* ---- ray crossings ---- */

/* One ray direction: the axis kz of its largest component, the other two kx, ky, the shear
 * (sx, sy, sz) = (d[kx] / d[kz], d[ky] / d[kz], 1 / d[kz]) and 1 / d. */
typedef struct {
    int kx, ky, kz;
    double sx, sy, sz, inv[3];
} Ray;

/* the sign of edge function e of the edge from P to Q (ex, ey = Q - P, sheared): a zero
 * takes the sign it has for a point moved by (eps^2, eps), so that the two faces of an
 * edge (which see it with opposite directions) never both take it */
static inline int side(double e, double ex, double ey)
{
    if (e > 0)
        return 1;
    if (e < 0)
        return -1;
    if (ex < 0)
        return 1;
    if (ex > 0)
        return -1;
    return ey > 0 ? 1 : ey < 0 ? -1 : 0;
}

/* whether the ray from p crosses triangle t at a distance > 0 */
static int crosses(const double *t, const double *p, const Ray *r)
{
    double x[3], y[3], z[3];
    for (int v = 0; v < 3; v++) {
        double ax = t[3 * v + r->kx] - p[r->kx], ay = t[3 * v + r->ky] - p[r->ky], az = t[3 * v + r->kz] - p[r->kz];
        x[v] = ax - r->sx * az, y[v] = ay - r->sy * az, z[v] = r->sz * az;
    }
    /* u: edge B -> C, v: C -> A, w: A -> B */
    double u = x[2] * y[1] - y[2] * x[1], v = x[0] * y[2] - y[0] * x[2], w = x[1] * y[0] - y[1] * x[0];
    int su = side(u, x[2] - x[1], y[2] - y[1]), sv = side(v, x[0] - x[2], y[0] - y[2]),
        sw = side(w, x[1] - x[0], y[1] - y[0]);
    if (su == 0 || su != sv || su != sw)
        return 0;
    double tt = u * z[0] + v * z[1] + w * z[2];
    return su > 0 ? tt > 0 : tt < 0;
}

/* whether the ray from p meets box i grown by pad */
static inline int ray_box(const Tree *t, int64_t i, const double *p, const Ray *r, double pad)
{
    double near = -INFINITY, far = INFINITY;
    if (t->lo[3 * i] > t->hi[3 * i])
        return 0; /* empty */
    for (int k = 0; k < 3; k++) {
        double a = (t->lo[3 * i + k] - pad - p[k]) * r->inv[k], b = (t->hi[3 * i + k] + pad - p[k]) * r->inv[k];
        double mn = a < b ? a : b, mx = a < b ? b : a;
        near = mn > near ? mn : near;
        far = mx < far ? mx : far;
    }
    return near <= far && far >= 0;
}

static int parity_of(const Tree *t, const double *p, const Ray *r, double pad)
{
    int64_t stack[2 * MAX_DEPTH + 4];
    int top = 0, odd = 0;
    if (ray_box(t, 0, p, r, pad))
        stack[top++] = 0;
    while (top) {
        int64_t node = stack[--top];
        if (node >= t->leaves - 1) {
            int64_t s0 = (node - (t->leaves - 1)) * t->leaf, s1 = s0 + t->leaf;
            s1 = s1 < t->nf ? s1 : t->nf;
            for (int64_t s = s0; s < s1; s++)
                odd ^= crosses(t->tri + 9 * s, p, r);
            continue;
        }
        for (int64_t c = 2 * node + 1; c <= 2 * node + 2; c++)
            if (ray_box(t, c, p, r, pad))
                stack[top++] = c;
    }
    return odd;
}

typedef struct {
    Tree t;
    const double *points;
    const Ray *rays;
    int nrays;
    double pad;
    uint8_t *inside;
    int64_t n;
} Crossings;

static void crossings_job(void *ctx, int k, int count)
{
    Crossings *c = ctx;
    int64_t i0, i1;
    share(c->n, k, count, &i0, &i1);
    for (int64_t i = i0; i < i1; i++) {
        const double *p = c->points + 3 * i, *lo = c->t.lo, *hi = c->t.hi;
        if (p[0] < lo[0] || p[1] < lo[1] || p[2] < lo[2] || p[0] > hi[0] || p[1] > hi[1] || p[2] > hi[2]) {
            c->inside[i] = 0; /* outside the surface's box */
            continue;
        }
        int odd = 0, even = 0; /* rays stop once a majority is reached */
        for (int j = 0; j < c->nrays && 2 * odd <= c->nrays && 2 * even < c->nrays; j++) {
            int v = parity_of(&c->t, c->points + 3 * i, c->rays + j, c->pad);
            odd += v, even += !v;
        }
        c->inside[i] = 2 * odd > c->nrays;
    }
}

PyDoc_STRVAR(crossings_doc, "crossings(triangles (F,9) f8, order (F,) i8, thin (F,) u1, lo (N,3) f8, hi (N,3) f8, leaf, points (n,3) f8, "
                            "axes (K,3) i8, shear (K,3) f8, inverse (K,3) f8, pad, inside (n,) bool, threads): "
                            "parity._inside_numpy into ``inside``.");

static PyObject *crossings_py(PyObject *self, PyObject *args)
{
    PyObject *otri, *oorder, *othin, *olo, *ohi, *opts, *oaxes, *oshear, *oinv, *oinside;
    long long leaf;
    double pad;
    int threads;
    Tree t;
    PyArrayObject *pts, *axes, *shear, *inv, *inside;
    npy_intp n;
    if (!PyArg_ParseTuple(args, "OOOOOLOOOOdOi", &otri, &oorder, &othin, &olo, &ohi, &leaf, &opts, &oaxes, &oshear,
                          &oinv, &pad, &oinside, &threads) ||
        !get_tree(otri, oorder, othin, olo, ohi, leaf, &t) || !get_points(opts, &pts, &n) ||
        !get(oaxes, NPY_INT64, -1, &axes, "axes") || !get_out(oinside, NPY_BOOL, n, &inside, "inside"))
        return NULL;
    npy_intp k = PyArray_SIZE(axes) / 3;
    if (PyArray_SIZE(axes) != 3 * k || k < 1 || k > 64 || !get(oshear, NPY_FLOAT64, 3 * k, &shear, "shear") ||
        !get(oinv, NPY_FLOAT64, 3 * k, &inv, "inverse")) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "crossings: 1 to 64 rays");
        return NULL;
    }
    if (!(pad >= 0 && isfinite(pad)) || !finite_all(PyArray_DATA(shear), 3 * k)) {
        PyErr_SetString(PyExc_ValueError, "crossings: pad and shear must be finite");
        return NULL;
    }
    Ray rays[64];
    const int64_t *ax = PyArray_DATA(axes);
    const double *sh = PyArray_DATA(shear), *iv = PyArray_DATA(inv);
    for (npy_intp j = 0; j < k; j++) {
        int64_t x = ax[3 * j], y = ax[3 * j + 1], z = ax[3 * j + 2];
        if (x < 0 || x > 2 || y < 0 || y > 2 || z < 0 || z > 2 || x == y || y == z || x == z) {
            PyErr_SetString(PyExc_ValueError, "crossings: axes not a permutation of 0, 1, 2");
            return NULL;
        }
        for (int m = 0; m < 3; m++)
            if (!isfinite(iv[3 * j + m]) || iv[3 * j + m] == 0) {
                PyErr_SetString(PyExc_ValueError, "crossings: inverse direction must be finite and non-zero");
                return NULL;
            }
        rays[j] = (Ray){(int)x, (int)y, (int)z, sh[3 * j], sh[3 * j + 1], sh[3 * j + 2],
                        {iv[3 * j], iv[3 * j + 1], iv[3 * j + 2]}};
    }
    Crossings c = {t, PyArray_DATA(pts), rays, (int)k, pad, PyArray_DATA(inside), n};
    int count = n < THREAD_POINTS ? 1 : threads;
    Py_BEGIN_ALLOW_THREADS
    in_parallel(count, crossings_job, &c);
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

/* ---- the tree order ---- */

typedef struct {
    double key;
    int64_t id;
} Item;

static inline int before(Item a, Item b) { return a.key < b.key || (a.key == b.key && a.id < b.id); }

static int by_item(const void *x, const void *y)
{
    Item a = *(const Item *)x, b = *(const Item *)y;
    return before(a, b) ? -1 : before(b, a) ? 1 : 0;
}

/* a[0 .. k-1] the k least of a[0 .. n-1] (by key, then id; 0 < k < n) */
static void select_least(Item *a, int64_t n, int64_t k)
{
    int64_t lo = 0, hi = n - 1;
    for (int rounds = 0; hi > lo; rounds++) {
        if (rounds > 80) {
            qsort(a + lo, (size_t)(hi - lo + 1), sizeof(Item), by_item);
            return;
        }
        Item x = a[lo], y = a[lo + (hi - lo) / 2], z = a[hi], p;
        p = before(x, y) ? (before(y, z) ? y : before(x, z) ? z : x) : (before(x, z) ? x : before(y, z) ? z : y);
        int64_t i = lo, j = hi;
        while (i <= j) {
            while (before(a[i], p))
                i++;
            while (before(p, a[j]))
                j--;
            if (i <= j) {
                Item t = a[i];
                a[i++] = a[j], a[j--] = t;
            }
        }
        if (k <= j)
            hi = j;
        else if (k >= i)
            lo = i;
        else
            return;
    }
}

PyDoc_STRVAR(order_doc, "order(centres (F,3) f8, leaf, leaves) -> (F,) i8: distance.median_order from the faces' "
                        "box centres.");

static PyObject *order_py(PyObject *self, PyObject *args)
{
    PyObject *oc;
    PyArrayObject *ca;
    long long leaf, leaves;
    if (!PyArg_ParseTuple(args, "OLL", &oc, &leaf, &leaves) || !get(oc, NPY_FLOAT64, -1, &ca, "centres"))
        return NULL;
    npy_intp nf = PyArray_SIZE(ca) / 3;
    if (PyArray_NDIM(ca) != 2 || PyArray_DIM(ca, 1) != 3 || nf < 1 || leaf < 1 || leaf > 64 || leaves < 1 ||
        leaves > ((long long)1 << MAX_DEPTH) || (leaves & (leaves - 1)) != 0 || leaves * leaf < nf ||
        (leaves > 1 && leaves / 2 * leaf >= nf)) {
        PyErr_SetString(PyExc_ValueError, "order: bad shapes");
        return NULL;
    }
    const double *c = PyArray_DATA(ca);
    if (!finite_all(c, 3 * nf)) {
        PyErr_SetString(PyExc_ValueError, "order: non-finite centre");
        return NULL;
    }
    PyArrayObject *out = (PyArrayObject *)PyArray_SimpleNew(1, (npy_intp[]){nf}, NPY_INT64);
    Item *items = malloc(sizeof(Item) * (size_t)nf);
    if (!out || !items) {
        Py_XDECREF(out);
        free(items);
        return PyErr_NoMemory();
    }
    int64_t *o = PyArray_DATA(out);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < nf; i++)
        items[i] = (Item){0.0, i};
    for (int64_t size = leaves * leaf; size > leaf; size /= 2)
        for (int64_t s = 0; s < nf; s += size) {
            int64_t e = s + size < nf ? s + size : nf, half = size / 2;
            if (e - s <= half)
                continue;
            double lo[3], hi[3];
            for (int k = 0; k < 3; k++)
                lo[k] = hi[k] = c[3 * items[s].id + k];
            for (int64_t i = s + 1; i < e; i++)
                for (int k = 0; k < 3; k++) {
                    double v = c[3 * items[i].id + k];
                    lo[k] = v < lo[k] ? v : lo[k], hi[k] = v > hi[k] ? v : hi[k];
                }
            int axis = 0;
            for (int k = 1; k < 3; k++)
                if (hi[k] - lo[k] > hi[axis] - lo[axis])
                    axis = k;
            for (int64_t i = s; i < e; i++)
                items[i].key = c[3 * items[i].id + axis];
            select_least(items + s, e - s, half);
        }
    /* each leaf in face order */
    for (int64_t s = 0; s < nf; s += leaf) {
        int64_t e = s + leaf < nf ? s + leaf : nf;
        for (int64_t i = s + 1; i < e; i++)
            for (int64_t j = i; j > s && items[j].id < items[j - 1].id; j--) {
                Item t = items[j];
                items[j] = items[j - 1], items[j - 1] = t;
            }
    }
    for (npy_intp i = 0; i < nf; i++)
        o[i] = items[i].id;
    Py_END_ALLOW_THREADS
    free(items);
    return (PyObject *)out;
}

static PyMethodDef methods[] = {
    {"order", order_py, METH_VARARGS, order_doc},
    {"closest", closest, METH_VARARGS, closest_doc},
    {"crossings", crossings_py, METH_VARARGS, crossings_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cvolume", "Compiled closest points and ray parities over a triangle tree.", -1, methods,
};

PyMODINIT_FUNC PyInit__cvolume(void)
{
    import_array();
    return PyModule_Create(&module);
}
