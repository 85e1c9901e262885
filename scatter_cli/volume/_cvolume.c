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
 * closest() hands blocks of points to the threads as they finish the last; crossings()
 * cuts the points into fixed ranges, many a thread, taken the same way. The GIL is
 * released meanwhile.
 * Arrays are checked: a wrong shape, a non-finite value or an index out of range raises.
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
#include "_cthreads.h"

/* below this many points a call runs on one thread; crossings() cuts no range smaller */
#define THREAD_POINTS 512
#define MAX_DEPTH 62

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

/* whether ``leaves`` leaves of ``leaf`` slots each are the complete tree that
 * distance.leaf_count makes for nf faces (a power of two, the fewest that hold them;
 * compared without a product that could overflow) */
static int leaves_fit(int64_t leaves, int64_t leaf, int64_t nf)
{
    if (leaf < 1 || leaf > 64 || leaves < 1 || leaves > ((int64_t)1 << MAX_DEPTH) || (leaves & (leaves - 1)))
        return 0;
    int64_t least = (nf + leaf - 1) / leaf; /* leaves needed */
    return leaves >= least && (leaves == 1 || leaves / 2 < least);
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
    if (nodes < 1 || 2 * leaves - 1 != nodes || !leaves_fit(leaves, leaf, nf)) {
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
__attribute__((always_inline)) static inline void regions(const double *a, const double *b, const double *c,
                                                          const double *ab, const double *ac, const double *p,
                                                          double *q)
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

/* (inlined into closest_one: compiled for each of its targets, one call less per face) */
__attribute__((always_inline)) static inline double closest_on(const double *t, int thin, const double *p, double *q)
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


/* ---- the wide tree that closest() walks ----
 *
 * Built at each call from the heap tree: a node holds the boxes of four descendants two
 * levels down (one level for the root when the depth is odd), the heap tree's own float64
 * boxes side by side so that one vector operation tests all four (each lane computing
 * box_d2 exactly); the leaves (of the heap tree) hold the boxes of their faces the same
 * way, four at a time. A box is skipped only when it is farther than the best distance
 * plus ``tol``; testing the boxes two levels down without the one between skips less,
 * never more. (Boxes kept in float, rounded outward, halve their memory but cost a
 * conversion at every test: they measured slower.) */

#if defined(__GNUC__) && !defined(__clang__)
#pragma GCC diagnostic ignored "-Wpsabi" /* vectors pass only between inlined functions */
#endif
typedef double v4d __attribute__((vector_size(32)));
typedef int64_t v4l __attribute__((vector_size(32)));

typedef struct {
    v4d lo[3], hi[3]; /* four boxes, by axis; an empty one: lo +inf, hi -inf */
} Box4;

typedef struct {
    Box4 box;
    int64_t child[4]; /* >= 0: a wide node; < 0: ~j, leaf j of the heap tree */
} Wide;

/* Four faces: their boxes, and the disks holding them (centre, unit normal, radius; a
 * radius of +inf and a zero normal for a thin or tiny face, whose normal rounding may
 * tilt, or a slot without a face). Each disk is the face's smallest: about the middle of
 * its longest side when the angle across that side is not acute, else about its
 * circumcentre (either in the face's plane). A face lies in its disk, so its distance
 * is at least the disk's: sqrt(h^2 + max(0, l - r)^2), h the height over the disk's
 * plane, l the distance from the centre along the plane. The rounding of that (the
 * normal of a face that is not thin is within some 20 ulp of exact, each other step a
 * few ulp of the point's distance from the centre) is under 1e-14 times the largest
 * coordinate of the points and the surface, a hundredth of ``tol``: the disk is tested
 * against the best distance plus twice ``tol``, and so skips only faces farther than the
 * best plus tol. */
typedef struct {
    Box4 box;
    v4d c[3], n[3], r;
} Faces4;

/* The cylinders holding a wide node's four children (for children of at most CYLINDER
 * faces; the others and empty ones: radius and half height +inf): an axis (c, n, unit n:
 * along the faces' summed area normal, c at mid-height of their corners along it, so
 * that the cylinder is no taller than it must be) and, over the children's corners, the
 * greatest distance from the axis (r) and from the plane through c across it (t). A
 * face lies in the cylinder of its node, so its distance is at least the cylinder's,
 * sqrt(max(0, |h| - t)^2 + max(0, l - r)^2) for a point at height h over that plane and
 * distance l from the axis; rounding moves that by less than 1e-14 times the largest
 * coordinate, and it is tested as the disks are (against the best distance plus twice
 * ``tol``). */
typedef struct {
    v4d c[3], n[3], r, t;
} Cyl4;

#define CYLINDER 64

typedef struct {
    Wide *nodes;      /* nodes[0] is the root's */
    Cyl4 *cyl;        /* per node */
    uint8_t *cyls;    /* per node: whether it has a cylinder (a child of at most CYLINDER faces) */
    Faces4 *faces;    /* per leaf j (and an empty leaf ``leaves``): quads faces j * quads ... */
    int64_t quads;    /* quads of faces in a leaf: ceil(leaf / 4) */
    int64_t count, root; /* nodes made; the root's reference (a node, or ~0 for a single leaf) */
    int depth;        /* of the heap tree: leaves = 2^depth */
    int64_t nf, leaves, leaf; /* of the heap tree it was made from */
} WideTree;

static void box_lane(Box4 *b, int lane, const double *lo, const double *hi)
{
    int empty = !(lo[0] <= hi[0] && lo[1] <= hi[1] && lo[2] <= hi[2]);
    for (int k = 0; k < 3; k++) {
        b->lo[k][lane] = empty ? INFINITY : lo[k];
        b->hi[k][lane] = empty ? -INFINITY : hi[k];
    }
}

static void box_empty(Box4 *b)
{
    for (int k = 0; k < 3; k++)
        for (int lane = 0; lane < 4; lane++)
            b->lo[k][lane] = INFINITY, b->hi[k][lane] = -INFINITY;
}

/* the wide node of heap node i at depth d; its index */
/* lane of y: the cylinder of slots s0 .. s1 - 1 of t, its axis through the centre of box
 * lo, hi moved to mid-height; none when there are more than CYLINDER of them */
static void cylinder_lane(const Tree *t, Cyl4 *y, int lane, int64_t s0, int64_t s1, const double *lo, const double *hi)
{
    for (int k = 0; k < 3; k++)
        y->c[k][lane] = 0.0, y->n[k][lane] = 0.0;
    y->r[lane] = y->t[lane] = INFINITY;
    s1 = s1 < t->nf ? s1 : t->nf;
    if (s1 - s0 > CYLINDER || s1 <= s0)
        return;
    double n[3] = {0, 0, 0}, c[3], r2 = 0, h = 0;
    for (int64_t s = s0; s < s1; s++) {
        const double *f = t->tri + 9 * s;
        double ab[3], ac[3];
        for (int k = 0; k < 3; k++)
            ab[k] = f[3 + k] - f[k], ac[k] = f[6 + k] - f[k];
        n[0] += ab[1] * ac[2] - ab[2] * ac[1], n[1] += ab[2] * ac[0] - ab[0] * ac[2], n[2] += ab[0] * ac[1] - ab[1] * ac[0];
    }
    double nn = dot(n, n);
    if (!(nn > 1e-250 && nn < 1e250))
        return;
    double len = sqrt(nn), low = INFINITY, high = -INFINITY;
    for (int k = 0; k < 3; k++)
        n[k] /= len, c[k] = lo[k] * 0.5 + hi[k] * 0.5;
    for (int64_t s = s0; s < s1; s++)
        for (int v = 0; v < 3; v++) {
            const double *x = t->tri + 9 * s + 3 * v;
            double u[3] = {x[0] - c[0], x[1] - c[1], x[2] - c[2]}, e = dot(n, u);
            low = e < low ? e : low, high = e > high ? e : high;
        }
    for (int k = 0; k < 3; k++)
        c[k] += (low * 0.5 + high * 0.5) * n[k];
    for (int64_t s = s0; s < s1; s++)
        for (int v = 0; v < 3; v++) {
            const double *x = t->tri + 9 * s + 3 * v;
            double u[3] = {x[0] - c[0], x[1] - c[1], x[2] - c[2]}, e = dot(n, u);
            double l[3] = {u[0] - e * n[0], u[1] - e * n[1], u[2] - e * n[2]};
            h = fabs(e) > h ? fabs(e) : h, r2 = dot(l, l) > r2 ? dot(l, l) : r2;
        }
    for (int k = 0; k < 3; k++)
        y->c[k][lane] = c[k], y->n[k][lane] = n[k];
    y->r[lane] = sqrt(r2), y->t[lane] = h;
}

static int64_t wide_node(const Tree *t, WideTree *w, int64_t i, int d)
{
    int64_t at = w->count++;
    Cyl4 *y = w->cyl + at;
    for (int lane = 0; lane < 4; lane++)
        cylinder_lane(t, y, lane, 0, 0, NULL, NULL);
    int step = (w->depth - d) % 2 ? 1 : 2;
    int64_t first = step == 1 ? 2 * i + 1 : 4 * i + 3;
    Wide node;
    box_empty(&node.box);
    for (int lane = 0; lane < 4; lane++)
        node.child[lane] = ~t->leaves; /* the empty leaf */
    for (int lane = 0; lane < 2 * step; lane++) {
        int64_t c = first + lane;
        box_lane(&node.box, lane, t->lo + 3 * c, t->hi + 3 * c);
        if (node.box.lo[0][lane] > node.box.hi[0][lane])
            continue; /* empty */
        node.child[lane] = d + step == w->depth ? ~(c - (t->leaves - 1)) : wide_node(t, w, c, d + step);
        int64_t span = (int64_t)1 << (w->depth - d - step), first_leaf = (c + 1) * span - t->leaves;
        cylinder_lane(t, y, lane, first_leaf * t->leaf, (first_leaf + span) * t->leaf, t->lo + 3 * c, t->hi + 3 * c);
    }
    w->nodes[at] = node;
    w->cyls[at] = y->r[0] < INFINITY || y->r[1] < INFINITY || y->r[2] < INFINITY || y->r[3] < INFINITY;
    return at;
}

/* lane of q: the disk of face f (9 doubles), none when f is NULL */
static void disk_lane(Faces4 *q, int lane, const double *f)
{
    for (int k = 0; k < 3; k++)
        q->c[k][lane] = 0.0, q->n[k][lane] = 0.0;
    q->r[lane] = INFINITY;
    if (!f)
        return;
    const double *a = f, *b = f + 3, *c = f + 6;
    double ab[3], ac[3], bc[3], n[3], g[3], r2 = 0;
    for (int k = 0; k < 3; k++)
        ab[k] = b[k] - a[k], ac[k] = c[k] - a[k], bc[k] = c[k] - b[k];
    n[0] = ab[1] * ac[2] - ab[2] * ac[1], n[1] = ab[2] * ac[0] - ab[0] * ac[2], n[2] = ab[0] * ac[1] - ab[1] * ac[0];
    double nn = dot(n, n), longest = dot(ab, ab);
    longest = dot(ac, ac) > longest ? dot(ac, ac) : longest;
    longest = dot(bc, bc) > longest ? dot(bc, bc) : longest;
    /* not thin (distance.THIN), nor so small that the products lose bits, nor overflowing */
    if (!(nn > 1e-250 && nn < 1e250 && nn >= 0.01 * longest * longest))
        return;
    /* the angles at a, b and c: acute when these are positive */
    double at_a = dot(ab, ac), at_b = -dot(ab, bc), at_c = dot(ac, bc);
    if (at_a <= 0 || at_b <= 0 || at_c <= 0) {
        const double *u = at_a <= 0 ? b : a, *v = at_a <= 0 || at_b <= 0 ? c : b; /* the longest side */
        for (int k = 0; k < 3; k++)
            g[k] = u[k] * 0.5 + v[k] * 0.5;
    } else { /* a + (|ac|^2 (n x ab) + |ab|^2 (ac x n)) / (2 |n|^2) */
        double x[3], y[3], sac = dot(ac, ac), sab = dot(ab, ab), half = 0.5 / nn;
        x[0] = n[1] * ab[2] - n[2] * ab[1], x[1] = n[2] * ab[0] - n[0] * ab[2], x[2] = n[0] * ab[1] - n[1] * ab[0];
        y[0] = ac[1] * n[2] - ac[2] * n[1], y[1] = ac[2] * n[0] - ac[0] * n[2], y[2] = ac[0] * n[1] - ac[1] * n[0];
        for (int k = 0; k < 3; k++)
            g[k] = a[k] + (sac * x[k] + sab * y[k]) * half;
    }
    for (int v = 0; v < 3; v++) {
        double d[3] = {f[3 * v] - g[0], f[3 * v + 1] - g[1], f[3 * v + 2] - g[2]};
        r2 = dot(d, d) > r2 ? dot(d, d) : r2;
    }
    double len = sqrt(nn);
    for (int k = 0; k < 3; k++)
        q->c[k][lane] = g[k], q->n[k][lane] = n[k] / len;
    q->r[lane] = sqrt(r2);
}

static void wide_free(WideTree *w)
{
    free(w->nodes), free(w->faces), free(w->cyl), free(w->cyls);
}

/* size bytes aligned to 64 (aligned_alloc wants a whole number of 64-byte blocks) */
static void *alloc64(size_t size)
{
    return aligned_alloc(64, (size + 63) / 64 * 64);
}

/* the wide tree of t; 0 when out of memory */
static int wide_tree(const Tree *t, WideTree *w)
{
    int depth = 0;
    while (((int64_t)1 << depth) < t->leaves)
        depth++;
    w->depth = depth, w->quads = (t->leaf + 3) / 4, w->count = 0;
    w->nf = t->nf, w->leaves = t->leaves, w->leaf = t->leaf;
    int64_t count = 1; /* wide nodes: the root, then at depths d0, d0 + 2, ... under the leaves' */
    for (int d = depth % 2 ? 1 : 2; d < depth; d += 2)
        count += (int64_t)1 << d;
    w->nodes = alloc64(sizeof(Wide) * (size_t)count);
    w->cyl = alloc64(sizeof(Cyl4) * (size_t)count);
    w->cyls = malloc((size_t)count);
    w->faces = alloc64(sizeof(Faces4) * (size_t)((t->leaves + 1) * w->quads));
    if (!w->nodes || !w->faces || !w->cyl || !w->cyls) {
        wide_free(w);
        return 0;
    }
    for (int64_t j = 0; j <= t->leaves; j++)
        for (int64_t q = 0; q < w->quads; q++) {
            Faces4 *fq = w->faces + j * w->quads + q;
            Box4 *b = &fq->box;
            box_empty(b);
            for (int lane = 0; lane < 4; lane++)
                disk_lane(fq, lane, NULL);
            for (int lane = 0; lane < 4; lane++) {
                int64_t s = j * t->leaf + 4 * q + lane;
                if (4 * q + lane >= t->leaf || s >= t->nf)
                    break;
                const double *f = t->tri + 9 * s;
                double lo[3], hi[3];
                for (int k = 0; k < 3; k++) {
                    lo[k] = f[k] < f[3 + k] ? f[k] : f[3 + k], hi[k] = f[k] < f[3 + k] ? f[3 + k] : f[k];
                    lo[k] = f[6 + k] < lo[k] ? f[6 + k] : lo[k], hi[k] = f[6 + k] > hi[k] ? f[6 + k] : hi[k];
                }
                box_lane(b, lane, lo, hi);
                disk_lane(fq, lane, f);
            }
        }
    w->root = depth == 0 ? ~(int64_t)0 : wide_node(t, w, 0, 0);
    return 1;
}

/* the lanes of *m (each 0 or -1) as bits */
static inline unsigned mask4(const v4l *m)
{
    return (unsigned)(((*m)[0] & 1) | ((*m)[1] & 2) | ((*m)[2] & 4) | ((*m)[3] & 8));
}

/* squared distances from p to the four boxes of b, each computed as box_d2 does (an empty
 * box: +inf) */
__attribute__((always_inline)) static inline v4d box4_d2(const Box4 *b, const double *p)
{
    v4d s = {0, 0, 0, 0};
    for (int k = 0; k < 3; k++) {
        v4d lo = b->lo[k] - p[k], hi = p[k] - b->hi[k];
        v4l m = lo > hi;
        v4d g = (v4d)(((v4l)lo & m) | ((v4l)hi & ~m));
        g = (v4d)((v4l)g & (g > 0));
        s += g * g;
    }
    return s;
}

/* the heights h of p over the four planes through c[k] across unit n[k], and its
 * distances l from the four axes (c, n) */
__attribute__((always_inline)) static inline void axial4(const v4d c[3], const v4d n[3], const double *p, v4d *h, v4d *l)
{
    v4d v0 = p[0] - c[0], v1 = p[1] - c[1], v2 = p[2] - c[2];
    *h = n[0] * v0 + n[1] * v1 + n[2] * v2;
    v4d l0 = v0 - *h * n[0], l1 = v1 - *h * n[1], l2 = v2 - *h * n[2];
    *l = l0 * l0 + l1 * l1 + l2 * l2;
    for (int lane = 0; lane < 4; lane++)
        (*l)[lane] = sqrt((*l)[lane]);
}

/* squared distances from p to the disks of the four faces of q (0 where there is none) */
__attribute__((always_inline)) static inline v4d disk4_d2(const Faces4 *q, const double *p)
{
    v4d h, l;
    axial4(q->c, q->n, p, &h, &l);
    v4d g = l - q->r;
    g = (v4d)((v4l)g & (g > 0));
    return h * h + g * g;
}

/* squared distances from p to the four cylinders of y */
__attribute__((always_inline)) static inline v4d cyl4_d2(const Cyl4 *y, const double *p)
{
    v4d h, l;
    axial4(y->c, y->n, p, &h, &l);
    v4d a = (v4d)((v4l)h & ~(v4l){INT64_MIN, INT64_MIN, INT64_MIN, INT64_MIN}) - y->t, g = l - y->r;
    a = (v4d)((v4l)a & (a > 0)), g = (v4d)((v4l)g & (g > 0));
    return a * a + g * g;
}

/* the closest face of p; *slot: on entry a slot whose face starts the search (or -1),
 * on return the slot of the answer */
TARGETS static void closest_one(const Tree *t, const WideTree *w, const double *p, double tol, double *dist, double *cq,
                        int64_t *face, int64_t *slot)
{
    double best = INFINITY, bound = INFINITY, disk = INFINITY, q[3], bq[3] = {NAN, NAN, NAN};
    int64_t bestf = INT64_MAX, bests = -1, stack[4 * MAX_DEPTH + 8];
    double sd[4 * MAX_DEPTH + 8];
    if (*slot >= 0) {
        best = closest_on(t->tri + 9 * *slot, t->thin[*slot], p, bq), bestf = t->order[*slot], bests = *slot;
        double r = sqrt(best) + tol, rd = r + tol;
        bound = r * r, disk = rd * rd;
    }
    int top = 0;
    stack[0] = w->root, sd[0] = box_d2(t, 0, p), top = 1;
    while (top) {
        top--;
        int64_t ref = stack[top];
        if (sd[top] > bound)
            continue;
        if (ref < 0) {
            int64_t j = ~ref, s0 = j * t->leaf, s1 = s0 + t->leaf;
            s1 = s1 < t->nf ? s1 : t->nf;
            for (int64_t qd = 0; qd < w->quads && s0 + 4 * qd < s1; qd++) {
                const Faces4 *fq = w->faces + j * w->quads + qd;
                v4d fd = box4_d2(&fq->box, p), dd = disk4_d2(fq, p);
                /* the faces in the bounds, one branch each; a lane is tested again when a
                 * face before it has narrowed them */
                int64_t left = s1 - s0 - 4 * qd;
                v4l out = (fd > bound) | (dd > disk);
                unsigned in = ~mask4(&out) & (left >= 4 ? 15u : (1u << left) - 1);
                for (; in; in &= in - 1) {
                    int lane = __builtin_ctz(in);
                    int64_t s = s0 + 4 * qd + lane;
                    if (fd[lane] > bound || dd[lane] > disk)
                        continue;
#ifdef COUNT
                    __atomic_fetch_add(&faces_tested, 1, __ATOMIC_RELAXED);
#endif
                    double d2 = closest_on(t->tri + 9 * s, t->thin[s], p, q);
                    int64_t f = t->order[s];
                    if (d2 < best || (d2 == best && f < bestf)) {
                        best = d2, bestf = f, bests = s, bq[0] = q[0], bq[1] = q[1], bq[2] = q[2];
                        double r = sqrt(best) + tol, rd = r + tol;
                        bound = r * r, disk = rd * rd;
                    }
                }
            }
            continue;
        }
#ifdef COUNT
        __atomic_fetch_add(&nodes_opened, 1, __ATOMIC_RELAXED);
#endif
        const Wide *n = w->nodes + ref;
        /* (the nodes near the root have no cylinder: one predictable branch, no square root) */
        v4d d = box4_d2(&n->box, p), dy = w->cyls[ref] ? cyl4_d2(w->cyl + ref, p) : (v4d){0, 0, 0, 0};
        /* the children within the bound, the nearest on top */
        int64_t cr[4];
        double cd[4];
        int m = 0;
        for (int lane = 0; lane < 4; lane++) {
            if (d[lane] > bound || dy[lane] > disk)
                continue;
            int at = m++;
            while (at > 0 && cd[at - 1] < d[lane])
                cd[at] = cd[at - 1], cr[at] = cr[at - 1], at--;
            cd[at] = d[lane], cr[at] = n->child[lane];
        }
        for (int k = 0; k < m; k++)
            stack[top] = cr[k], sd[top++] = cd[k];
    }
    *dist = sqrt(best), *face = bestf, *slot = bests;
    cq[0] = bq[0], cq[1] = bq[1], cq[2] = bq[2];
}

typedef struct {
    Tree t;
    const WideTree *w;
    const double *points;
    const int64_t *visit; /* the points in this order (near ones in turn) */
    double tol;
    double *dist, *closest;
    int64_t *face;
    int64_t n;
} Closest;

/* points a piece holds (in visit order): threads that finish early take more pieces */
#define CLOSEST_BLOCK 1024

static void closest_job(void *ctx, int k, int count)
{
    Closest *c = ctx;
    int64_t slot = -1; /* where the walk starts: any slot gives the same answer */
    (void)count;
    int64_t i0 = (int64_t)k * CLOSEST_BLOCK, i1 = i0 + CLOSEST_BLOCK < c->n ? i0 + CLOSEST_BLOCK : c->n;
    for (int64_t j = i0; j < i1; j++) {
        int64_t i = c->visit[j];
        closest_one(&c->t, c->w, c->points + 3 * i, c->tol, c->dist + i, c->closest + 3 * i, c->face + i, &slot);
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

#define WIDE "scatter_cli._cvolume.wide"

static void wide_release(PyObject *capsule)
{
    WideTree *w = PyCapsule_GetPointer(capsule, WIDE);
    if (w) {
        wide_free(w);
        free(w);
    }
}

PyDoc_STRVAR(wide_doc, "wide(triangles (F,9) f8, order (F,) i8, thin (F,) u1, lo (N,3) f8, hi (N,3) f8, leaf) -> the wide "
                       "tree that closest() walks, made once for a tree (an opaque object).");

static PyObject *wide_py(PyObject *self, PyObject *args)
{
    PyObject *otri, *oorder, *othin, *olo, *ohi;
    long long leaf;
    Tree t;
    if (!PyArg_ParseTuple(args, "OOOOOL", &otri, &oorder, &othin, &olo, &ohi, &leaf) ||
        !get_tree(otri, oorder, othin, olo, ohi, leaf, &t))
        return NULL;
    WideTree *w = malloc(sizeof(WideTree));
    int ok = 0;
    if (w) {
        Py_BEGIN_ALLOW_THREADS
        ok = wide_tree(&t, w);
        Py_END_ALLOW_THREADS
    }
    if (!ok) {
        free(w);
        return PyErr_NoMemory();
    }
    PyObject *capsule = PyCapsule_New(w, WIDE, wide_release);
    if (!capsule) {
        wide_free(w);
        free(w);
    }
    return capsule;
}

PyDoc_STRVAR(closest_doc, "closest(triangles (F,9) f8, order (F,) i8, thin (F,) u1, lo (N,3) f8, hi (N,3) f8, leaf, points (n,3) f8, "
                          "visit (n,) i8, tol, distance (n,) f8, closest (n,3) f8, face (n,) i8, threads[, wide]): "
                          "distance._closest_numpy into the three output arrays. ``wide``: wide() of the same arrays (made "
                          "at the call when absent or None; one of another tree of the same sizes gives wrong answers, "
                          "never a read out of bounds).");

static PyObject *closest(PyObject *self, PyObject *args)
{
    PyObject *otri, *oorder, *othin, *olo, *ohi, *opts, *ovisit, *odist, *oclosest, *oface, *owide = Py_None;
    long long leaf;
    double tol;
    int threads;
    Tree t;
    PyArrayObject *pts, *visit, *dist, *cl, *face;
    npy_intp n;
    if (!PyArg_ParseTuple(args, "OOOOOLOOdOOOi|O", &otri, &oorder, &othin, &olo, &ohi, &leaf, &opts, &ovisit, &tol,
                          &odist, &oclosest, &oface, &threads, &owide) ||
        !get_tree(otri, oorder, othin, olo, ohi, leaf, &t) || !get_points(opts, &pts, &n) || !get_visit(ovisit, n, &visit) ||
        !get_out(odist, NPY_FLOAT64, n, &dist, "distance") || !get_out(oclosest, NPY_FLOAT64, 3 * n, &cl, "closest") ||
        !get_out(oface, NPY_INT64, n, &face, "face"))
        return NULL;
    if (!(tol >= 0 && isfinite(tol))) {
        PyErr_SetString(PyExc_ValueError, "closest: tol must be finite and >= 0");
        return NULL;
    }
    WideTree own, *w = &own;
    if (owide != Py_None) {
        w = PyCapsule_GetPointer(owide, WIDE);
        if (!w)
            return NULL;
        if (w->nf != t.nf || w->leaves != t.leaves || w->leaf != t.leaf) {
            PyErr_SetString(PyExc_ValueError, "closest: the wide tree is another tree's");
            return NULL;
        }
    }
    Closest c = {t, w, PyArray_DATA(pts), PyArray_DATA(visit), tol, PyArray_DATA(dist), PyArray_DATA(cl), PyArray_DATA(face), n};
    int pieces = (int)((n + CLOSEST_BLOCK - 1) / CLOSEST_BLOCK), ok = 1;
    Py_BEGIN_ALLOW_THREADS
    if (w == &own)
        ok = wide_tree(&t, &own);
    if (ok) {
        in_pieces(pieces, n < THREAD_POINTS ? 1 : threads, closest_job, &c);
        if (w == &own)
            wide_free(&own);
    }
    Py_END_ALLOW_THREADS
    if (!ok)
        return PyErr_NoMemory();
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
    int pieces = pieces_for(n, THREAD_POINTS, threads);
    Py_BEGIN_ALLOW_THREADS
    in_pieces(pieces, threads, crossings_job, &c);
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

/* ---- the tree order ---- */

typedef struct {
    double key;
    double c[3]; /* the face's centre, carried along: each level reads its items in turn, not centres by id */
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

PyDoc_STRVAR(order_doc, "order(triangles (F,9) f8, leaf, leaves) -> (F,) i8: distance.median_order, from the "
                        "centres of the faces' boxes.");

static PyObject *order_py(PyObject *self, PyObject *args)
{
    PyObject *ot;
    PyArrayObject *ta;
    long long leaf, leaves;
    if (!PyArg_ParseTuple(args, "OLL", &ot, &leaf, &leaves) || !get(ot, NPY_FLOAT64, -1, &ta, "triangles"))
        return NULL;
    npy_intp nf = PyArray_SIZE(ta) / 9;
    if (PyArray_NDIM(ta) != 2 || PyArray_DIM(ta, 1) != 9 || nf < 1 || !leaves_fit(leaves, leaf, nf)) {
        PyErr_SetString(PyExc_ValueError, "order: bad shapes");
        return NULL;
    }
    const double *tri = PyArray_DATA(ta);
    if (!finite_all(tri, 9 * nf)) {
        PyErr_SetString(PyExc_ValueError, "order: non-finite coordinate");
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
    for (npy_intp i = 0; i < nf; i++) {
        const double *f = tri + 9 * i;
        Item it = {0.0, {0, 0, 0}, i};
        for (int k = 0; k < 3; k++) { /* as np.minimum and np.maximum of the corners, then lo * 0.5 + hi * 0.5 */
            double lo = f[k] < f[3 + k] ? f[k] : f[3 + k], hi = f[k] > f[3 + k] ? f[k] : f[3 + k];
            lo = lo < f[6 + k] ? lo : f[6 + k], hi = hi > f[6 + k] ? hi : f[6 + k];
            it.c[k] = lo * 0.5 + hi * 0.5;
        }
        items[i] = it;
    }
    for (int64_t size = leaves * leaf; size > leaf; size /= 2)
        for (int64_t s = 0; s < nf; s += size) {
            int64_t e = s + size < nf ? s + size : nf, half = size / 2;
            if (e - s <= half)
                continue;
            double lo[3], hi[3];
            for (int k = 0; k < 3; k++)
                lo[k] = hi[k] = items[s].c[k];
            for (int64_t i = s + 1; i < e; i++)
                for (int k = 0; k < 3; k++) {
                    double v = items[i].c[k];
                    lo[k] = v < lo[k] ? v : lo[k], hi[k] = v > hi[k] ? v : hi[k];
                }
            int axis = 0;
            for (int k = 1; k < 3; k++)
                if (hi[k] - lo[k] > hi[axis] - lo[axis])
                    axis = k;
            for (int64_t i = s; i < e; i++)
                items[i].key = items[i].c[axis];
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

/* ---- the tree's other arrays ---- */

/* np.maximum's: NaN when either is */
static inline double nan_max(double a, double b) { return a != a || a > b ? a : b; }

PyDoc_STRVAR(thin_doc, "thin(triangles (F,9) f8) -> (F,) u1: distance.thin_faces.");

static PyObject *thin_py(PyObject *self, PyObject *args)
{
    PyObject *ot;
    PyArrayObject *ta;
    npy_intp nf;
    if (!PyArg_ParseTuple(args, "O", &ot) || !get_rows(ot, NPY_FLOAT64, 9, &ta, &nf, "triangles"))
        return NULL;
    PyArrayObject *out = (PyArrayObject *)PyArray_SimpleNew(1, (npy_intp[]){nf}, NPY_UINT8);
    if (!out)
        return NULL;
    const double *tri = PyArray_DATA(ta), limit = 0.1 * 0.1; /* distance.THIN squared, as Python rounds it */
    uint8_t *thin = PyArray_DATA(out);
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < nf; i++) {
        const double *a = tri + 9 * i, *b = a + 3, *c = a + 6;
        double ab[3], ac[3], bc[3];
        for (int k = 0; k < 3; k++)
            ab[k] = b[k] - a[k], ac[k] = c[k] - a[k], bc[k] = c[k] - b[k];
        double n[3] = {ab[1] * ac[2] - ab[2] * ac[1], ab[2] * ac[0] - ab[0] * ac[2], ab[0] * ac[1] - ab[1] * ac[0]};
        double longest = nan_max(nan_max(dot(ab, ab), dot(ac, ac)), dot(bc, bc));
        thin[i] = dot(n, n) <= limit * longest * longest;
    }
    Py_END_ALLOW_THREADS
    return (PyObject *)out;
}

PyDoc_STRVAR(boxes_doc, "boxes(triangles (F,9) f8, leaf, leaves) -> (lo, hi), (2 leaves - 1, 3) f8 each: "
                        "distance.node_boxes.");

static PyObject *boxes_py(PyObject *self, PyObject *args)
{
    PyObject *ot;
    PyArrayObject *ta;
    npy_intp nf;
    long long leaf, leaves;
    if (!PyArg_ParseTuple(args, "OLL", &ot, &leaf, &leaves) || !get_rows(ot, NPY_FLOAT64, 9, &ta, &nf, "triangles"))
        return NULL;
    if (!leaves_fit(leaves, leaf, nf)) {
        PyErr_SetString(PyExc_ValueError, "boxes: bad shapes");
        return NULL;
    }
    npy_intp dims[2] = {2 * (npy_intp)leaves - 1, 3};
    PyArrayObject *olo = (PyArrayObject *)PyArray_SimpleNew(2, dims, NPY_FLOAT64);
    PyArrayObject *ohi = (PyArrayObject *)PyArray_SimpleNew(2, dims, NPY_FLOAT64);
    if (!olo || !ohi) {
        Py_XDECREF(olo), Py_XDECREF(ohi);
        return NULL;
    }
    const double *tri = PyArray_DATA(ta);
    double *lo = PyArray_DATA(olo), *hi = PyArray_DATA(ohi);
    Py_BEGIN_ALLOW_THREADS
    for (int64_t j = 0; j < leaves; j++) { /* leaf j: node leaves - 1 + j; no faces: lo +inf, hi -inf */
        double *l = lo + 3 * (leaves - 1 + j), *h = hi + 3 * (leaves - 1 + j);
        for (int k = 0; k < 3; k++)
            l[k] = INFINITY, h[k] = -INFINITY;
        int64_t s1 = (j + 1) * leaf < nf ? (j + 1) * leaf : nf;
        for (int64_t s = j * leaf; s < s1; s++)
            for (int v = 0; v < 3; v++)
                for (int k = 0; k < 3; k++) {
                    double x = tri[9 * s + 3 * v + k];
                    l[k] = x < l[k] ? x : l[k], h[k] = x > h[k] ? x : h[k];
                }
    }
    for (int64_t i = leaves - 2; i >= 0; i--)
        for (int k = 0; k < 3; k++) {
            double a = lo[3 * (2 * i + 1) + k], b = lo[3 * (2 * i + 2) + k];
            double c = hi[3 * (2 * i + 1) + k], d = hi[3 * (2 * i + 2) + k];
            lo[3 * i + k] = a < b ? a : b, hi[3 * i + k] = c > d ? c : d;
        }
    Py_END_ALLOW_THREADS
    return Py_BuildValue("NN", olo, ohi);
}

PyDoc_STRVAR(visit_doc, "visit(points (n,3) f8) -> (n,) i8: distance.visit_order (the points along a Morton curve).");

static PyObject *visit_py(PyObject *self, PyObject *args)
{
    PyObject *opts;
    PyArrayObject *pts;
    npy_intp n;
    if (!PyArg_ParseTuple(args, "O", &opts) || !get_points(opts, &pts, &n))
        return NULL;
    PyArrayObject *out = (PyArrayObject *)PyArray_SimpleNew(1, (npy_intp[]){n}, NPY_INT64);
    uint64_t *code = malloc(sizeof(uint64_t) * (size_t)(n > 0 ? n : 1));
    int ok = out && code;
    if (ok) {
        Py_BEGIN_ALLOW_THREADS
        morton10(PyArray_DATA(pts), n, code);
        ok = stable_order(code, n, 30, PyArray_DATA(out));
        Py_END_ALLOW_THREADS
    }
    free(code);
    if (!ok) {
        Py_XDECREF(out);
        return PyErr_NoMemory();
    }
    return (PyObject *)out;
}

static PyMethodDef methods[] = {
    {"order", order_py, METH_VARARGS, order_doc},
    {"thin", thin_py, METH_VARARGS, thin_doc},
    {"boxes", boxes_py, METH_VARARGS, boxes_doc},
    {"visit", visit_py, METH_VARARGS, visit_doc},
    {"wide", wide_py, METH_VARARGS, wide_doc},
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
