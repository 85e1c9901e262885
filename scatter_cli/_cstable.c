/* Compiled stable placement: the same numbers as stable.py's NumPy path.
 *
 * Face keys and areas, the arrivals of a range of faces before a time, their arrival
 * order, and the points of arrivals: point by point, the integer and float64 operations
 * that the NumPy code does on whole arrays, in the same order (built with
 * -ffp-contract=off), so the two paths give byte-identical output. The GIL is released while they run.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define GOLDEN 0x9E3779B97F4A7C15ULL
#define COUNT_BITS 5
#define LANES 4
#define PASS 128
#define LANE_FACES 4

static int get(PyObject *obj, int type, npy_intp size, PyArrayObject **out, const char *name)
{
    if (!PyArray_Check(obj) || PyArray_TYPE((PyArrayObject *)obj) != type ||
        !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)obj) ||
        (size >= 0 && PyArray_SIZE((PyArrayObject *)obj) != size)) {
        PyErr_Format(PyExc_TypeError, "%s: wrong dtype, order or size", name);
        return 0;
    }
    *out = (PyArrayObject *)obj;
    return 1;
}

static inline uint64_t mix(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

static inline uint64_t lane(uint64_t state, uint64_t offset) { return mix(offset * GOLDEN + state); }

static inline double to_unit(uint64_t z) { return (double)(z >> 11) * (1.0 / 9007199254740992.0); }

static inline uint64_t bits(double x)
{
    uint64_t u;
    memcpy(&u, &x, 8);
    return u;
}

static inline int less(const double *x, const double *b)
{
    return (x[0] < b[0]) | ((x[0] == b[0]) & ((x[1] < b[1]) | ((x[1] == b[1]) & (x[2] < b[2]))));
}

/* The corner (0, 1 or 2) that is smallest in (x, y, z) order, the first of equal ones;
 * without branches: which corner it is cannot be predicted. */
static inline int smallest(const double *c0, const double *c1, const double *c2)
{
    int one = less(c1, c0);
    const double *best = one ? c1 : c0;
    int two = less(c2, best);
    return two ? 2 : one;
}

PyDoc_STRVAR(faces_doc, "faces(vertices (V,3) f8, faces (F,3) i8, start, stop, seed_word, rot (F,) u1, key (F,) u8, "
                        "area (F,) f8): canonical rotation, key and area of faces start..stop-1 (stable.FaceTable).");

static PyObject *faces(PyObject *self, PyObject *args)
{
    PyObject *overts, *ofaces, *orot, *okey, *oarea;
    PyArrayObject *verts, *fa, *rot_a, *key_a, *area_a;
    Py_ssize_t start, stop;
    unsigned long long seed;
    if (!PyArg_ParseTuple(args, "OOnnKOOO", &overts, &ofaces, &start, &stop, &seed, &orot, &okey, &oarea) ||
        !get(overts, NPY_FLOAT64, -1, &verts, "vertices") || !get(ofaces, NPY_INT64, -1, &fa, "faces"))
        return NULL;
    npy_intp nf = PyArray_SIZE(fa) / 3, nv = PyArray_SIZE(verts) / 3;
    if (!get(orot, NPY_UINT8, nf, &rot_a, "rot") || !get(okey, NPY_UINT64, nf, &key_a, "key") ||
        !get(oarea, NPY_FLOAT64, nf, &area_a, "area"))
        return NULL;
    if (start < 0 || stop > nf || start > stop) {
        PyErr_SetString(PyExc_ValueError, "faces: range out of bounds");
        return NULL;
    }
    const double *v = PyArray_DATA(verts);
    const int64_t *f = PyArray_DATA(fa);
    uint8_t *rot = PyArray_DATA(rot_a);
    uint64_t *key = PyArray_DATA(key_a);
    double *area = PyArray_DATA(area_a);
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    /* LANE_FACES faces at a time: their hashes (nine dependent mixes each) run side by side */
    for (npy_intp i0 = start; i0 < stop; i0 += LANE_FACES) {
        int count = stop - i0 < LANE_FACES ? (int)(stop - i0) : LANE_FACES;
        double t[LANE_FACES][9];
        uint64_t h[LANE_FACES];
        for (int q = 0; q < LANE_FACES; q++) {
            npy_intp i = i0 + (q < count ? q : 0);
            double c[3][3];
            for (int k = 0; k < 3; k++) {
                int64_t vi = f[3 * i + k];
                if (vi < 0 || vi >= nv) {
                    bad = 1;
                    vi = 0;
                }
                for (int a = 0; a < 3; a++)
                    c[k][a] = v[3 * vi + a] + 0.0;
            }
            int r = smallest(c[0], c[1], c[2]);
            for (int k = 0; k < 3; k++)
                for (int a = 0; a < 3; a++)
                    t[q][3 * k + a] = c[(r + k) % 3][a];
            if (q < count)
                rot[i] = (uint8_t)r;
            h[q] = seed;
        }
        for (int w = 0; w < 9; w++)
            for (int q = 0; q < LANE_FACES; q++) {
                h[q] ^= bits(t[q][w]);
                h[q] += GOLDEN;
                h[q] = mix(h[q]);
            }
        for (int q = 0; q < count; q++) {
            double e1[3], e2[3], n[3];
            for (int a = 0; a < 3; a++) {
                e1[a] = t[q][3 + a] - t[q][a];
                e2[a] = t[q][6 + a] - t[q][a];
            }
            for (int a = 0; a < 3; a++)
                n[a] = e1[(a + 1) % 3] * e2[(a + 2) % 3] - e1[(a + 2) % 3] * e2[(a + 1) % 3];
            double s = n[0] * n[0];
            s += n[1] * n[1];
            s += n[2] * n[2];
            key[i0 + q] = h[q];
            area[i0 + q] = 0.5 * sqrt(s);
        }
    }
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "faces: vertex index out of range");
        return NULL;
    }
    Py_RETURN_NONE;
}

/* Blocks of one face covering [0, tau): stable._blocks_before. */
static inline int64_t blocks_before(double tau, double length)
{
    int64_t nb = (int64_t)(floor(tau / length) + 1);
    if ((double)nb * length < tau)
        nb++;
    return nb;
}

static inline int poisson(double u, const double *cdf, int m)
{
    int c = 0; /* searchsorted(cdf, u, 'right'): entries <= u (cdf increases) */
    if (m >= 8) { /* the first eight without a branch: almost every count is below 8 */
        for (int k = 0; k < 8; k++)
            c += cdf[k] <= u;
        if (c < 8)
            return c;
    }
    while (c < m && cdf[c] <= u)
        c++;
    return c;
}

PyDoc_STRVAR(arrivals_doc, "arrivals(key (F,) u8, rate (F,) f8, tau, block_mean, cdf (K,) f8, first, last, cb, t, id)"
                           " -> count: stable.arrivals of faces first..last-1, written to t (f8) and id (u8: used face "
                           "<< cb | counter) while they fit (None: only counted); the count is returned either way.");

static PyObject *arrivals(PyObject *self, PyObject *args)
{
    PyObject *okey, *orate, *ocdf, *ot, *oid;
    PyArrayObject *key_a, *rate_a, *cdf_a, *t_a = NULL, *id_a = NULL;
    double tau, mean;
    Py_ssize_t first, last;
    int cb;
    if (!PyArg_ParseTuple(args, "OOddOnniOO", &okey, &orate, &tau, &mean, &ocdf, &first, &last, &cb, &ot, &oid) ||
        !get(okey, NPY_UINT64, -1, &key_a, "key") || !get(orate, NPY_FLOAT64, PyArray_SIZE(key_a), &rate_a, "rate") ||
        !get(ocdf, NPY_FLOAT64, -1, &cdf_a, "cdf"))
        return NULL;
    int fill = ot != Py_None;
    if (fill && (!get(ot, NPY_FLOAT64, -1, &t_a, "t") || !get(oid, NPY_UINT64, PyArray_SIZE(t_a), &id_a, "id")))
        return NULL;
    if (first < 0 || last > PyArray_SIZE(key_a) || first > last || PyArray_SIZE(cdf_a) >= (1 << COUNT_BITS) ||
        cb <= COUNT_BITS || cb >= 64 || (last > 0 && ((uint64_t)(last - 1) >> (64 - cb)) != 0)) {
        PyErr_SetString(PyExc_ValueError, "arrivals: bad range, table or counter bits");
        return NULL;
    }
    const uint64_t *key = PyArray_DATA(key_a);
    const double *rate = PyArray_DATA(rate_a), *cdf = PyArray_DATA(cdf_a);
    int m = (int)PyArray_SIZE(cdf_a);
    npy_intp cap = fill ? PyArray_SIZE(t_a) : 0, n = 0;
    double *t = fill ? PyArray_DATA(t_a) : NULL;
    uint64_t *id = fill ? PyArray_DATA(id_a) : NULL;
    int64_t max_blocks = (int64_t)1 << (cb - COUNT_BITS);
    int over = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = first; i < last && !over; i++) {
        double length = mean / rate[i];
        int64_t nb = blocks_before(tau, length);
        if (nb > max_blocks) {
            over = 1;
            break;
        }
        uint64_t base = (uint64_t)i << cb;
        for (int64_t b = 0; b < nb; b++) {
            uint64_t state = lane(key[i], (uint64_t)(b + 1));
            int c = poisson(to_unit(lane(state, 0)), cdf, m);
            if (n + c > cap && (double)(b + 1) * length < tau) {
                n += c; /* only counted: every time (b + u) length is at most (b + 1) length, rounded too */
                continue;
            }
            for (int j = 0; j < c; j++) {
                double time = ((double)b + to_unit(lane(state, (uint64_t)(1 + LANES * j)))) * length;
                if (n < cap) { /* written whether kept or not: the next one overwrites it */
                    t[n] = time;
                    id[n] = base | ((uint64_t)b << COUNT_BITS) | (uint64_t)j;
                }
                n += time < tau;
            }
        }
    }
    Py_END_ALLOW_THREADS
    if (over) {
        PyErr_SetString(PyExc_ValueError, "arrivals: a face has more blocks than the counter bits hold");
        return NULL;
    }
    return PyLong_FromSsize_t(n);
}

/* The sort key of a time: floor(t * scale), capped below total; non-decreasing in t. */
static inline int64_t time_key(double t, double scale, int64_t total)
{
    int64_t k = (int64_t)(t * scale);
    return k < total ? k : total - 1;
}

typedef struct {
    PyArrayObject *t, *id, *starts, *counts;
    npy_intp size, runs;
} Runs;

/* The runs t[starts[s]:starts[s] + counts[s]] of (t, id) arrays, checked. */
static int get_runs(PyObject *ot, PyObject *oid, PyObject *ostarts, PyObject *ocounts, Runs *r)
{
    if (!get(ot, NPY_FLOAT64, -1, &r->t, "t") || !get(oid, NPY_UINT64, PyArray_SIZE(r->t), &r->id, "id") ||
        !get(ostarts, NPY_INT64, -1, &r->starts, "starts") ||
        !get(ocounts, NPY_INT64, PyArray_SIZE(r->starts), &r->counts, "counts"))
        return 0;
    r->size = PyArray_SIZE(r->t);
    r->runs = PyArray_SIZE(r->starts);
    const int64_t *st = PyArray_DATA(r->starts), *ct = PyArray_DATA(r->counts);
    for (npy_intp s = 0; s < r->runs; s++)
        if (st[s] < 0 || ct[s] < 0 || st[s] > r->size - ct[s]) {
            PyErr_SetString(PyExc_ValueError, "order: run out of bounds");
            return 0;
        }
    return 1;
}

PyDoc_STRVAR(order_count_doc, "order_count(t, id, starts, counts, scale, shift, total, hist (C,) i8): add to hist[q] "
                              "the arrivals of the runs whose time key (stable.kernel_order) >> shift is q.");

static PyObject *order_count(PyObject *self, PyObject *args)
{
    PyObject *ot, *oid, *ostarts, *ocounts, *ohist;
    PyArrayObject *hist_a;
    Runs r;
    double scale;
    int shift;
    long long total;
    if (!PyArg_ParseTuple(args, "OOOOdiLO", &ot, &oid, &ostarts, &ocounts, &scale, &shift, &total, &ohist) ||
        !get_runs(ot, oid, ostarts, ocounts, &r) || !get(ohist, NPY_INT64, -1, &hist_a, "hist"))
        return NULL;
    if (shift < 0 || shift > 30 || total < 1 || PyArray_SIZE(hist_a) != ((total - 1) >> shift) + 1 || !(scale >= 0)) {
        PyErr_SetString(PyExc_ValueError, "order_count: bad buckets");
        return NULL;
    }
    const double *t = PyArray_DATA(r.t);
    const int64_t *st = PyArray_DATA(r.starts), *ct = PyArray_DATA(r.counts);
    int64_t *hist = PyArray_DATA(hist_a);
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp s = 0; s < r.runs; s++)
        for (npy_intp i = st[s]; i < st[s] + ct[s]; i++) {
            if (!(t[i] >= 0.0)) {
                bad = 1;
                continue;
            }
            hist[time_key(t[i], scale, total) >> shift]++;
        }
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "order_count: a time is negative or not a number");
        return NULL;
    }
    Py_RETURN_NONE;
}

PyDoc_STRVAR(order_scatter_doc, "order_scatter(t, id, starts, counts, scale, shift, total, next (C,) i8, t_out, id_out): "
                                "write each arrival of the runs to position next[q]++ of its coarse bucket q.");

static PyObject *order_scatter(PyObject *self, PyObject *args)
{
    PyObject *ot, *oid, *ostarts, *ocounts, *onext, *otout, *oidout;
    PyArrayObject *next_a, *tout_a, *idout_a;
    Runs r;
    double scale;
    int shift;
    long long total;
    if (!PyArg_ParseTuple(args, "OOOOdiLOOO", &ot, &oid, &ostarts, &ocounts, &scale, &shift, &total, &onext, &otout,
                          &oidout) ||
        !get_runs(ot, oid, ostarts, ocounts, &r) || !get(onext, NPY_INT64, -1, &next_a, "next") ||
        !get(otout, NPY_FLOAT64, -1, &tout_a, "t_out") || !get(oidout, NPY_UINT64, PyArray_SIZE(tout_a), &idout_a, "id_out"))
        return NULL;
    if (shift < 0 || shift > 30 || total < 1 || PyArray_SIZE(next_a) != ((total - 1) >> shift) + 1 || !(scale >= 0)) {
        PyErr_SetString(PyExc_ValueError, "order_scatter: bad buckets");
        return NULL;
    }
    const double *t = PyArray_DATA(r.t);
    const uint64_t *id = PyArray_DATA(r.id);
    const int64_t *st = PyArray_DATA(r.starts), *ct = PyArray_DATA(r.counts);
    int64_t *next = PyArray_DATA(next_a), m = PyArray_SIZE(tout_a);
    double *to = PyArray_DATA(tout_a);
    uint64_t *io = PyArray_DATA(idout_a);
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp s = 0; s < r.runs; s++)
        for (npy_intp i = st[s]; i < st[s] + ct[s]; i++) {
            int64_t at = next[time_key(t[i] >= 0.0 ? t[i] : 0.0, scale, total) >> shift]++;
            if (at < 0 || at >= m) {
                bad = 1;
                continue;
            }
            to[at] = t[i];
            io[at] = id[i];
        }
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "order_scatter: a bucket overflows the output");
        return NULL;
    }
    Py_RETURN_NONE;
}

/* Arrival order: (time, face key, counter). */
static inline int earlier(double ta, uint64_t ia, double tb, uint64_t ib, const uint64_t *key, int cb, uint64_t mask)
{
    if (ta != tb)
        return ta < tb;
    uint64_t ka = key[ia >> cb], kb = key[ib >> cb];
    if (ka != kb)
        return ka < kb;
    return (ia & mask) < (ib & mask);
}

PyDoc_STRVAR(order_sort_doc, "order_sort(t, id, bounds (C+1,) i8, q0, q1, scale, shift, total, key (U,) u8, cb) -> "
                             "duplicates: sort coarse buckets q0..q1-1 (t[bounds[q]:bounds[q+1]], id likewise) in place "
                             "by (time, face key, counter): a counting sort on the rest of the time key, then each "
                             "fine bucket exactly; duplicates: whether two consecutive arrivals have equal time, key "
                             "and counter (stable._duplicates).");

static PyObject *order_sort(PyObject *self, PyObject *args)
{
    PyObject *ot, *oid, *obounds, *okey;
    PyArrayObject *t_a, *id_a, *bounds_a, *key_a;
    Py_ssize_t q0, q1;
    double scale;
    int shift, cb;
    long long total;
    if (!PyArg_ParseTuple(args, "OOOnndiLOi", &ot, &oid, &obounds, &q0, &q1, &scale, &shift, &total, &okey, &cb) ||
        !get(ot, NPY_FLOAT64, -1, &t_a, "t") || !get(oid, NPY_UINT64, PyArray_SIZE(t_a), &id_a, "id") ||
        !get(obounds, NPY_INT64, -1, &bounds_a, "bounds") || !get(okey, NPY_UINT64, -1, &key_a, "key"))
        return NULL;
    npy_intp m = PyArray_SIZE(t_a), nq = PyArray_SIZE(bounds_a) - 1, nu = PyArray_SIZE(key_a);
    const int64_t *bounds = PyArray_DATA(bounds_a);
    int ok = shift >= 0 && shift <= 30 && total >= 1 && nq == ((total - 1) >> shift) + 1 && q0 >= 0 && q0 <= q1 &&
             q1 <= nq && cb > COUNT_BITS && cb < 64 && scale >= 0 && bounds[0] == 0 && bounds[nq] == m;
    npy_intp most = 0;
    for (npy_intp q = 0; ok && q < nq; q++) {
        ok = bounds[q] <= bounds[q + 1];
        most = bounds[q + 1] - bounds[q] > most ? bounds[q + 1] - bounds[q] : most;
    }
    double *t = PyArray_DATA(t_a);
    uint64_t *id = PyArray_DATA(id_a);
    const uint64_t *key = PyArray_DATA(key_a);
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "order_sort: bad buckets");
        return NULL;
    }
    int64_t fine = (int64_t)1 << shift;
    double *tb = malloc((most ? most : 1) * sizeof(double));
    uint64_t *ib = malloc((most ? most : 1) * sizeof(uint64_t));
    int64_t *next = malloc((fine + 1) * sizeof(int64_t));
    uint32_t *fk = malloc((most ? most : 1) * sizeof(uint32_t)); /* each arrival's fine key */
    if (!tb || !ib || !next || !fk) {
        free(tb);
        free(ib);
        free(next);
        free(fk);
        return PyErr_NoMemory();
    }
    uint64_t mask = ((uint64_t)1 << cb) - 1;
    int dup = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp q = q0; q < q1 && ok; q++) {
        npy_intp lo = bounds[q], n = bounds[q + 1] - lo;
        memset(next, 0, (fine + 1) * sizeof(int64_t));
        for (npy_intp i = 0; i < n; i++) {
            double x = t[lo + i];
            int64_t k = x >= 0.0 ? time_key(x, scale, total) : -1;
            ok &= (id[lo + i] >> cb) < (uint64_t)nu && (k >> shift) == q;
            tb[i] = x;
            ib[i] = id[lo + i];
            fk[i] = (uint32_t)(k & (fine - 1));
            next[fk[i] + 1]++;
        }
        if (n < 2 || !ok)
            continue;
        for (int64_t f = 0; f < fine; f++)
            next[f + 1] += next[f];
        for (npy_intp i = 0; i < n; i++) {
            int64_t at = lo + next[fk[i]]++;
            t[at] = tb[i];
            id[at] = ib[i];
        }
        /* fine bucket f now ends at lo + next[f]: insertion sort each, exactly */
        int64_t a0 = lo;
        for (int64_t f = 0; f < fine; f++) {
            int64_t hi = lo + next[f];
            for (int64_t a = a0 + 1; a < hi; a++) {
                double tv = t[a];
                uint64_t iv = id[a];
                int64_t c = a;
                while (c > a0 && earlier(tv, iv, t[c - 1], id[c - 1], key, cb, mask)) {
                    t[c] = t[c - 1];
                    id[c] = id[c - 1];
                    c--;
                }
                t[c] = tv;
                id[c] = iv;
            }
            a0 = hi;
        }
        /* equal times have equal keys, so a duplicate pair lies within one bucket */
        for (npy_intp a = lo + 1; a < lo + n && !dup; a++)
            dup = t[a] == t[a - 1] && key[id[a] >> cb] == key[id[a - 1] >> cb] && (id[a] & mask) == (id[a - 1] & mask);
    }
    Py_END_ALLOW_THREADS
    free(tb);
    free(ib);
    free(next);
    free(fk);
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "order_sort: an arrival is not in its bucket");
        return NULL;
    }
    return PyBool_FromLong(dup);
}

PyDoc_STRVAR(place_doc, "place(id (n,) u8, cb, key (U,) u8, face (U,) i8 or None, faces (F,3) i8, vertices (V,3) f8, "
                        "points (n,3) f8, b (n,2) f8 or None, face_out (n,) i8 or None, in_face_order): points of arrivals "
                        "id (used face << cb | counter) on one instance (stable.StableSource._place, square-root warp), "
                        "their warp's b and their faces; face None: used face k is face k. in_face_order: computed in "
                        "face order (same bytes).");

/* Points of arrivals at[k] (k < count), in passes over blocks of points, so that the cache
 * misses of a pass (keys, face rows, then vertices) are independent and overlap. */
typedef struct {
    const uint64_t *id, *key;
    const int64_t *face, *fa;
    const double *v;
    double *pts, *bo;
    int64_t *face_out;
    npy_intp nu, nf, nv;
    int cb;
} Place;

static int place_block(const Place *p, const int32_t *at, npy_intp i0, npy_intp count)
{
    int bad = 0;
    uint64_t mask = ((uint64_t)1 << p->cb) - 1;
    int64_t vi[PASS][3], fi[PASS];
    uint64_t key[PASS];
    for (npy_intp k = 0; k < count; k++) {
        npy_intp o = at ? at[k] : i0 + k;
        uint64_t u = p->id[o] >> p->cb;
        if (u >= (uint64_t)p->nu) {
            bad = 1;
            u = 0;
        }
        int64_t f = p->face ? p->face[u] : (int64_t)u;
        if (f < 0 || f >= p->nf) {
            bad = 1;
            f = 0;
        }
        fi[k] = f;
        key[k] = p->key[u];
    }
    for (npy_intp k = 0; k < count; k++)
        for (int c = 0; c < 3; c++) {
            int64_t x = p->fa[3 * fi[k] + c];
            if (x < 0 || x >= p->nv) {
                bad = 1;
                x = 0;
            }
            vi[k][c] = x;
        }
    for (npy_intp k = 0; k < count; k++) {
        npy_intp o = at ? at[k] : i0 + k;
        uint64_t c = p->id[o] & mask;
        uint64_t state = lane(key[k], (c >> COUNT_BITS) + 1);
        uint64_t j = (c & ((1u << COUNT_BITS) - 1)) * LANES;
        double b1 = 1.0 - sqrt(to_unit(lane(state, j + 2)));
        double b2 = (1.0 - b1) * to_unit(lane(state, j + 3));
        if (p->bo) {
            p->bo[2 * o] = b1;
            p->bo[2 * o + 1] = b2;
        }
        if (p->face_out)
            p->face_out[o] = fi[k];
        const double *w[5] = {p->v + 3 * vi[k][0], p->v + 3 * vi[k][1], p->v + 3 * vi[k][2]};
        w[3] = w[0];
        w[4] = w[1];
        /* the canonical rotation, as faces() finds it (-0.0 and 0.0 compare equal) */
        int r = smallest(w[0], w[1], w[2]);
        const double *c0 = w[r], *c1 = w[r + 1], *c2 = w[r + 2];
        for (int a = 0; a < 3; a++) {
            double col = (c1[a] - c0[a]) * b1;
            col += (c2[a] - c0[a]) * b2;
            col += c0[a];
            p->pts[3 * o + a] = col;
        }
    }
    return bad;
}

static PyObject *place(PyObject *self, PyObject *args)
{
    PyObject *oid, *okey, *oface, *ofaces, *overts, *opts, *ob, *ofout;
    PyArrayObject *id_a, *key_a, *face_a = NULL, *faces_a, *verts_a, *pts_a, *b_a = NULL, *fout_a = NULL;
    int cb, in_face_order;
    if (!PyArg_ParseTuple(args, "OiOOOOOOOp", &oid, &cb, &okey, &oface, &ofaces, &overts, &opts, &ob, &ofout,
                          &in_face_order) ||
        !get(oid, NPY_UINT64, -1, &id_a, "id") || !get(okey, NPY_UINT64, -1, &key_a, "key") ||
        (oface != Py_None && !get(oface, NPY_INT64, PyArray_SIZE(key_a), &face_a, "face")) ||
        !get(ofaces, NPY_INT64, -1, &faces_a, "faces") || !get(overts, NPY_FLOAT64, -1, &verts_a, "vertices") ||
        !get(opts, NPY_FLOAT64, 3 * PyArray_SIZE(id_a), &pts_a, "points") ||
        (ob != Py_None && !get(ob, NPY_FLOAT64, 2 * PyArray_SIZE(id_a), &b_a, "b")) ||
        (ofout != Py_None && !get(ofout, NPY_INT64, PyArray_SIZE(id_a), &fout_a, "face_out")))
        return NULL;
    if (cb <= COUNT_BITS || cb >= 64) {
        PyErr_SetString(PyExc_ValueError, "place: bad counter bits");
        return NULL;
    }
    npy_intp n = PyArray_SIZE(id_a);
    Place p = {PyArray_DATA(id_a), PyArray_DATA(key_a), face_a ? PyArray_DATA(face_a) : NULL, PyArray_DATA(faces_a),
               PyArray_DATA(verts_a), PyArray_DATA(pts_a), b_a ? PyArray_DATA(b_a) : NULL,
               fout_a ? PyArray_DATA(fout_a) : NULL,
               PyArray_SIZE(key_a), PyArray_SIZE(faces_a) / 3, PyArray_SIZE(verts_a) / 3, cb};
    int bad = 0, sorted = in_face_order && n >= 2 * PASS && n < ((npy_intp)1 << 31);
    int32_t *at = NULL, *next = NULL;
    int64_t buckets = 1;
    int shift = 0;
    if (sorted) {
        int bits = 1;
        while (bits < 20 && ((npy_intp)8 << bits) < n) /* about 8 points a bucket, as _csampling's draw_sorted */
            bits++;
        buckets = (int64_t)1 << bits;
        while (((uint64_t)(p.nu - 1) >> shift) >= (uint64_t)buckets)
            shift++;
        at = malloc(n * sizeof(int32_t));
        next = calloc(buckets + 1, sizeof(int32_t));
        if (!at || !next) {
            free(at);
            free(next);
            return PyErr_NoMemory();
        }
    }
    Py_BEGIN_ALLOW_THREADS
    if (sorted) { /* a counting sort of the points by the leading bits of their used face */
        for (npy_intp k = 0; k < n; k++) {
            uint64_t q = (p.id[k] >> cb) >> shift;
            next[(q < (uint64_t)buckets ? q : (uint64_t)buckets - 1) + 1]++;
        }
        for (int64_t q = 0; q < buckets; q++)
            next[q + 1] += next[q];
        for (npy_intp k = 0; k < n; k++) {
            uint64_t q = (p.id[k] >> cb) >> shift;
            at[next[q < (uint64_t)buckets ? q : (uint64_t)buckets - 1]++] = (int32_t)k;
        }
    }
    for (npy_intp i0 = 0; i0 < n; i0 += PASS)
        bad |= place_block(&p, at ? at + i0 : NULL, i0, n - i0 < PASS ? n - i0 : PASS);
    Py_END_ALLOW_THREADS
    free(at);
    free(next);
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "place: index out of range");
        return NULL;
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"faces", faces, METH_VARARGS, faces_doc},
    {"arrivals", arrivals, METH_VARARGS, arrivals_doc},
    {"order_count", order_count, METH_VARARGS, order_count_doc},
    {"order_scatter", order_scatter, METH_VARARGS, order_scatter_doc},
    {"order_sort", order_sort, METH_VARARGS, order_sort_doc},
    {"place", place, METH_VARARGS, place_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cstable", "Compiled stable placement, byte-identical to stable.py's NumPy path.", -1,
    methods,
};

PyMODINIT_FUNC PyInit__cstable(void)
{
    import_array();
    return PyModule_Create(&module);
}
