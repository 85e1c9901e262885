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
#include "_ckernel.h"
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define GOLDEN 0x9E3779B97F4A7C15ULL
#define COUNT_BITS 5
#define LANES 4
#define PASS 128
#define LANE_FACES 4


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

/* A face's placement row: canonical corner c0, then c1 - c0 and c2 - c0 (the differences
 * place() would take), so a point is row[3 + a] b1 + row[6 + a] b2 + row[a]. */
static inline void corner_row(const double *c0, const double *c1, const double *c2, double *row)
{
    for (int a = 0; a < 3; a++) {
        row[a] = c0[a];
        row[3 + a] = c1[a] - c0[a];
        row[6 + a] = c2[a] - c0[a];
    }
}

PyDoc_STRVAR(faces_doc, "faces(vertices (V,3) f8, faces (F,3) i8, start, stop, seed_word, rot (F,) u1, key (F,) u8, "
                        "area (F,) f8, corners (F,9) f8 or None): canonical rotation, key and area of faces "
                        "start..stop-1 (stable.FaceTable), and their placement rows (see place).");

static PyObject *faces(PyObject *self, PyObject *args)
{
    PyObject *overts, *ofaces, *orot, *okey, *oarea, *ocorners;
    PyArrayObject *verts, *fa, *rot_a, *key_a, *area_a, *corners_a = NULL;
    Py_ssize_t start, stop;
    unsigned long long seed;
    if (!PyArg_ParseTuple(args, "OOnnKOOOO", &overts, &ofaces, &start, &stop, &seed, &orot, &okey, &oarea, &ocorners) ||
        !get(overts, NPY_FLOAT64, -1, &verts, "vertices") || !get(ofaces, NPY_INT64, -1, &fa, "faces"))
        return NULL;
    npy_intp nf = PyArray_SIZE(fa) / 3, nv = PyArray_SIZE(verts) / 3;
    if (!get(orot, NPY_UINT8, nf, &rot_a, "rot") || !get(okey, NPY_UINT64, nf, &key_a, "key") ||
        !get(oarea, NPY_FLOAT64, nf, &area_a, "area") ||
        (ocorners != Py_None && !get(ocorners, NPY_FLOAT64, 9 * nf, &corners_a, "corners")))
        return NULL;
    if (start < 0 || stop > nf || start > stop) {
        PyErr_SetString(PyExc_ValueError, "faces: range out of bounds");
        return NULL;
    }
    const double *v = PyArray_DATA(verts);
    const int64_t *f = PyArray_DATA(fa);
    uint8_t *rot = PyArray_DATA(rot_a);
    uint64_t *key = PyArray_DATA(key_a);
    double *area = PyArray_DATA(area_a), *rows = corners_a ? PyArray_DATA(corners_a) : NULL;
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
            int64_t vi[3];
            for (int k = 0; k < 3; k++) {
                vi[k] = f[3 * i + k];
                if (vi[k] < 0 || vi[k] >= nv) {
                    bad = 1;
                    vi[k] = 0;
                }
                for (int a = 0; a < 3; a++)
                    c[k][a] = v[3 * vi[k] + a] + 0.0;
            }
            int r = smallest(c[0], c[1], c[2]);
            for (int k = 0; k < 3; k++)
                for (int a = 0; a < 3; a++)
                    t[q][3 * k + a] = c[(r + k) % 3][a];
            if (q < count) {
                rot[i] = (uint8_t)r;
                if (rows) /* from the vertices as stored (-0.0 kept): what place() reads */
                    corner_row(v + 3 * vi[r], v + 3 * vi[(r + 1) % 3], v + 3 * vi[(r + 2) % 3], rows + 9 * i);
            }
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

/* The sort key of a time: floor(t * scale), capped below total; non-decreasing in t. */
static inline int64_t time_key(double t, double scale, int64_t total)
{
    int64_t k = (int64_t)(t * scale);
    return k < total ? k : total - 1;
}

/* Coarse buckets of the time key: bucket q holds keys q << shift .. ((q + 1) << shift) - 1. */
static int check_buckets(double scale, int shift, long long total, npy_intp buckets, const char *name)
{
    if (shift < 0 || shift > 30 || total < 1 || buckets != ((total - 1) >> shift) + 1 || !(scale >= 0)) {
        PyErr_Format(PyExc_ValueError, "%s: bad buckets", name);
        return 0;
    }
    return 1;
}

/* Where arrivals go: the bucket of a time (time_key >> shift) and its next position. */
typedef struct {
    double tau, scale;
    int64_t total;
    int shift;
    int64_t *next;
    const int64_t *end;
    double *t;
    uint64_t *id;
} Bucketing;

/* A block of a face's arrivals: its state, the id of its arrival 0, its number and length. */
typedef struct {
    uint64_t state, id;
    double b, length;
} Block;

#define BATCH_BLOCKS 64
#define EXPAND 4 /* Poisson(2) exceeds 4 in 5 % of blocks */

/* The arrivals ent[0..n-1] (block << COUNT_BITS | j) of blocks blk: times, those before
 * tau written to their buckets. */
static void bucket_batch(const Bucketing *o, const Block *blk, const uint32_t *ent, int n)
{
    for (int e = 0; e < n; e++) {
        const Block *k = blk + (ent[e] >> COUNT_BITS);
        uint64_t j = ent[e] & ((1u << COUNT_BITS) - 1);
        double time = (k->b + to_unit(lane(k->state, 1 + LANES * j))) * k->length;
        if (!(time < o->tau))
            continue;
        int64_t q = time_key(time, o->scale, o->total) >> o->shift;
        int64_t at = o->next[q]++;
        if (at < o->end[q]) {
            o->t[at] = time;
            o->id[at] = k->id | j;
        }
    }
}

PyDoc_STRVAR(arrivals_doc,
             "arrivals(key (F,) u8, rate (F,) f8, tau, block_mean, cdf (K,) f8, first, last, cb, scale, shift, total, "
             "next (C,) i8, end (C,) i8, t, id): stable.arrivals of faces first..last-1, each written to position "
             "next[q]++ of t (f8) and id (u8: used face << cb | counter), q its coarse bucket (time key >> shift, "
             "the key floor(t scale) capped below total), while next[q] < end[q]; next[q] - its first value is "
             "bucket q's count either way.");

static PyObject *arrivals(PyObject *self, PyObject *args)
{
    PyObject *okey, *orate, *ocdf, *onext, *oend, *ot, *oid;
    PyArrayObject *key_a, *rate_a, *cdf_a, *next_a, *end_a, *t_a, *id_a;
    double tau, mean, scale;
    Py_ssize_t first, last;
    int cb, shift;
    long long total;
    if (!PyArg_ParseTuple(args, "OOddOnnidiLOOOO", &okey, &orate, &tau, &mean, &ocdf, &first, &last, &cb, &scale,
                          &shift, &total, &onext, &oend, &ot, &oid) ||
        !get(okey, NPY_UINT64, -1, &key_a, "key") || !get(orate, NPY_FLOAT64, PyArray_SIZE(key_a), &rate_a, "rate") ||
        !get(ocdf, NPY_FLOAT64, -1, &cdf_a, "cdf") || !get(onext, NPY_INT64, -1, &next_a, "next") ||
        !get(oend, NPY_INT64, PyArray_SIZE(next_a), &end_a, "end") || !get(ot, NPY_FLOAT64, -1, &t_a, "t") ||
        !get(oid, NPY_UINT64, PyArray_SIZE(t_a), &id_a, "id") ||
        !check_buckets(scale, shift, total, PyArray_SIZE(next_a), "arrivals"))
        return NULL;
    npy_intp nq = PyArray_SIZE(next_a), size = PyArray_SIZE(t_a);
    int64_t *next = PyArray_DATA(next_a);
    const int64_t *end = PyArray_DATA(end_a);
    int ok = first >= 0 && last <= PyArray_SIZE(key_a) && first <= last && PyArray_SIZE(cdf_a) < (1 << COUNT_BITS) &&
             cb > COUNT_BITS && cb < 64 && (last == 0 || ((uint64_t)(last - 1) >> (64 - cb)) == 0);
    for (npy_intp q = 0; ok && q < nq; q++)
        ok = next[q] >= 0 && next[q] <= end[q] && end[q] <= size;
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "arrivals: bad range, table, counter bits or buckets");
        return NULL;
    }
    const uint64_t *key = PyArray_DATA(key_a);
    const double *rate = PyArray_DATA(rate_a), *cdf = PyArray_DATA(cdf_a);
    int m = (int)PyArray_SIZE(cdf_a);
    double *t = PyArray_DATA(t_a);
    uint64_t *id = PyArray_DATA(id_a);
    int64_t max_blocks = (int64_t)1 << (cb - COUNT_BITS);
    int over = 0;
    Py_BEGIN_ALLOW_THREADS
    Bucketing out = {tau, scale, total, shift, next, end, t, id};
    Block blk[BATCH_BLOCKS];
    uint32_t ent[BATCH_BLOCKS << COUNT_BITS];
    int nblk = 0, n = 0;
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
            blk[nblk] = (Block){state, base | ((uint64_t)b << COUNT_BITS), (double)b, length};
            /* arrival j of the batch's block k is entry k << COUNT_BITS | j; the first EXPAND
               are written whether the block has them or not (n advances by c), so that the
               count, which cannot be predicted, steers no branch in most blocks */
            uint32_t e = (uint32_t)nblk << COUNT_BITS;
            for (int j = 0; j < EXPAND; j++)
                ent[n + j] = e | (uint32_t)j;
            for (int j = EXPAND; j < c; j++)
                ent[n + j] = e | (uint32_t)j;
            n += c;
            if (++nblk == BATCH_BLOCKS) {
                bucket_batch(&out, blk, ent, n);
                nblk = n = 0;
            }
        }
    }
    if (nblk)
        bucket_batch(&out, blk, ent, n);
    Py_END_ALLOW_THREADS
    if (over) {
        PyErr_SetString(PyExc_ValueError, "arrivals: a face has more blocks than the counter bits hold");
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

PyDoc_STRVAR(order_doc,
             "order(t, id, start (C*P,) i8, count (C*P,) i8, parts P, q0, q1, scale, shift, total, key (U,) u8, cb, "
             "t_side, id_side) -> duplicates: arrival order, in place. Segment s = q P + p, at t[start[s]:start[s] + "
             "count[s]] (id likewise, segments in order and apart), holds arrivals of coarse bucket q; buckets "
             "q0..q1-1 are sorted by (time, face key, counter) and written to positions bounds[q] .. bounds[q + 1] - 1 "
             "(bounds: the counts' running sum), those below start[q0 P] to t_side and id_side from bounds[q0] on "
             "(the caller copies them once every bucket below q0 is sorted). duplicates: whether two consecutive "
             "arrivals have equal time, key and counter (stable._duplicates).");

static PyObject *order(PyObject *self, PyObject *args)
{
    PyObject *ot, *oid, *ostart, *ocount, *okey, *otside, *oidside;
    PyArrayObject *t_a, *id_a, *start_a, *count_a, *key_a, *tside_a, *idside_a;
    Py_ssize_t parts, q0, q1;
    double scale;
    int shift, cb;
    long long total;
    if (!PyArg_ParseTuple(args, "OOOOnnndiLOiOO", &ot, &oid, &ostart, &ocount, &parts, &q0, &q1, &scale, &shift,
                          &total, &okey, &cb, &otside, &oidside) ||
        !get(ot, NPY_FLOAT64, -1, &t_a, "t") || !get(oid, NPY_UINT64, PyArray_SIZE(t_a), &id_a, "id") ||
        !get(ostart, NPY_INT64, -1, &start_a, "start") ||
        !get(ocount, NPY_INT64, PyArray_SIZE(start_a), &count_a, "count") || !get(okey, NPY_UINT64, -1, &key_a, "key") ||
        !get(otside, NPY_FLOAT64, -1, &tside_a, "t_side") ||
        !get(oidside, NPY_UINT64, PyArray_SIZE(tside_a), &idside_a, "id_side"))
        return NULL;
    npy_intp size = PyArray_SIZE(t_a), nseg = PyArray_SIZE(start_a), nu = PyArray_SIZE(key_a);
    if (parts < 1 || nseg % parts || !check_buckets(scale, shift, total, nseg / parts, "order"))
        return NULL;
    npy_intp nq = nseg / parts;
    const int64_t *start = PyArray_DATA(start_a), *count = PyArray_DATA(count_a);
    /* segments in order, apart, inside the arrays: then bounds[q] <= start[q P], so bucket q's
       output overwrites only arrivals of buckets up to q */
    int ok = q0 >= 0 && q0 <= q1 && q1 <= nq && cb > COUNT_BITS && cb < 64;
    for (npy_intp s = 0; ok && s < nseg; s++)
        ok = start[s] >= 0 && count[s] >= 0 && count[s] <= (s + 1 < nseg ? start[s + 1] : size) - start[s];
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "order: bad buckets or segments");
        return NULL;
    }
    int64_t lo = 0, most = 0; /* bounds[q0], the largest bucket */
    for (npy_intp q = 0; q < nq; q++) {
        int64_t n = 0;
        for (npy_intp p = 0; p < parts; p++)
            n += count[q * parts + p];
        lo += q < q0 ? n : 0;
        most = n > most && q >= q0 && q < q1 ? n : most;
    }
    int64_t hi = lo; /* bounds[q1] */
    for (npy_intp s = q0 * parts; s < q1 * parts; s++)
        hi += count[s];
    int64_t lo0 = lo, direct = q0 < nq ? start[q0 * parts] : size; /* positions from direct on are written in place */
    if (PyArray_SIZE(tside_a) < (direct < hi ? direct : hi) - lo) {
        PyErr_SetString(PyExc_ValueError, "order: side arrays too small");
        return NULL;
    }
    double *t = PyArray_DATA(t_a), *ts = PyArray_DATA(tside_a);
    uint64_t *id = PyArray_DATA(id_a), *is = PyArray_DATA(idside_a);
    const uint64_t *key = PyArray_DATA(key_a);
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
        memset(next, 0, (fine + 1) * sizeof(int64_t));
        int64_t n = 0;
        for (npy_intp s = q * parts; s < (q + 1) * parts; s++)
            for (int64_t i = start[s]; i < start[s] + count[s]; i++, n++) {
                double x = t[i];
                int64_t k = x >= 0.0 ? time_key(x, scale, total) : -1;
                ok &= (id[i] >> cb) < (uint64_t)nu && (k >> shift) == q;
                fk[n] = (uint32_t)(k & (fine - 1));
                next[fk[n] + 1]++;
            }
        if (!ok)
            break;
        for (int64_t f = 0; f < fine; f++)
            next[f + 1] += next[f];
        n = 0;
        for (npy_intp s = q * parts; s < (q + 1) * parts; s++)
            for (int64_t i = start[s]; i < start[s] + count[s]; i++, n++) {
                int64_t at = next[fk[n]]++;
                tb[at] = t[i];
                ib[at] = id[i];
            }
        /* fine bucket f now ends at next[f]: insertion sort each, exactly */
        int64_t a0 = 0;
        for (int64_t f = 0; f < fine; f++) {
            int64_t hi = next[f];
            for (int64_t a = a0 + 1; a < hi; a++) {
                double tv = tb[a];
                uint64_t iv = ib[a];
                int64_t c = a;
                while (c > a0 && earlier(tv, iv, tb[c - 1], ib[c - 1], key, cb, mask)) {
                    tb[c] = tb[c - 1];
                    ib[c] = ib[c - 1];
                    c--;
                }
                tb[c] = tv;
                ib[c] = iv;
            }
            a0 = hi;
        }
        /* equal times have equal keys, so a duplicate pair lies within one bucket */
        for (int64_t a = 1; a < n && !dup; a++)
            dup = tb[a] == tb[a - 1] && key[ib[a] >> cb] == key[ib[a - 1] >> cb] && (ib[a] & mask) == (ib[a - 1] & mask);
        /* out: the first k below direct to the side arrays, the rest in place */
        int64_t k = direct - lo < 0 ? 0 : (direct - lo < n ? direct - lo : n);
        if (k) {
            memcpy(ts + (lo - lo0), tb, k * sizeof(double));
            memcpy(is + (lo - lo0), ib, k * sizeof(uint64_t));
        }
        memcpy(t + lo + k, tb + k, (n - k) * sizeof(double));
        memcpy(id + lo + k, ib + k, (n - k) * sizeof(uint64_t));
        lo += n;
    }
    Py_END_ALLOW_THREADS
    free(tb);
    free(ib);
    free(next);
    free(fk);
    if (!ok) {
        PyErr_SetString(PyExc_ValueError, "order: an arrival is not in its bucket");
        return NULL;
    }
    return PyBool_FromLong(dup);
}

PyDoc_STRVAR(place_doc, "place(id (n,) u8, cb, key (U,) u8, face (U,) i8 or None, faces (F,3) i8, vertices (V,3) f8, "
                        "corners (F,9) f8 or None, points (n,3) f8, b (n,2) f8 or None, face_out (n,) i8 or None, "
                        "in_face_order): points of arrivals id (used face << cb | counter) on one instance "
                        "(stable.StableSource._place, square-root warp), their warp's b and their faces; face None: used "
                        "face k is face k. corners: the faces' rows from faces(), read instead of the face and vertex "
                        "tables. in_face_order: computed in face order (same bytes).");

/* Points of arrivals at[k] (k < count), in passes over blocks of points, so that the cache
 * misses of a pass (keys and face rows, then vertices) are independent and overlap. */
typedef struct {
    const uint64_t *id, *key;
    const int64_t *face, *fa;
    const double *v, *rows;
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
        if (p->rows) { /* 72 bytes: at most two cache lines */
            __builtin_prefetch(p->rows + 9 * f);
            __builtin_prefetch(p->rows + 9 * f + 8);
        }
    }
    for (npy_intp k = 0; k < count && !p->rows; k++)
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
        double own[9];
        const double *row = p->rows ? p->rows + 9 * fi[k] : own;
        if (!p->rows) {
            const double *w[5] = {p->v + 3 * vi[k][0], p->v + 3 * vi[k][1], p->v + 3 * vi[k][2]};
            w[3] = w[0];
            w[4] = w[1];
            /* the canonical rotation, as faces() finds it (-0.0 and 0.0 compare equal) */
            int r = smallest(w[0], w[1], w[2]);
            corner_row(w[r], w[r + 1], w[r + 2], own);
        }
        for (int a = 0; a < 3; a++) {
            double col = row[3 + a] * b1;
            col += row[6 + a] * b2;
            col += row[a];
            p->pts[3 * o + a] = col;
        }
    }
    return bad;
}

static PyObject *place(PyObject *self, PyObject *args)
{
    PyObject *oid, *okey, *oface, *ofaces, *overts, *ocorners, *opts, *ob, *ofout;
    PyArrayObject *id_a, *key_a, *face_a = NULL, *faces_a, *verts_a, *corners_a = NULL, *pts_a, *b_a = NULL,
                  *fout_a = NULL;
    int cb, in_face_order;
    if (!PyArg_ParseTuple(args, "OiOOOOOOOOp", &oid, &cb, &okey, &oface, &ofaces, &overts, &ocorners, &opts, &ob,
                          &ofout, &in_face_order) ||
        !get(oid, NPY_UINT64, -1, &id_a, "id") || !get(okey, NPY_UINT64, -1, &key_a, "key") ||
        (oface != Py_None && !get(oface, NPY_INT64, PyArray_SIZE(key_a), &face_a, "face")) ||
        !get(ofaces, NPY_INT64, -1, &faces_a, "faces") || !get(overts, NPY_FLOAT64, -1, &verts_a, "vertices") ||
        (ocorners != Py_None && !get(ocorners, NPY_FLOAT64, 3 * PyArray_SIZE(faces_a), &corners_a, "corners")) ||
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
               PyArray_DATA(verts_a), corners_a ? PyArray_DATA(corners_a) : NULL, PyArray_DATA(pts_a),
               b_a ? PyArray_DATA(b_a) : NULL, fout_a ? PyArray_DATA(fout_a) : NULL,
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
    {"order", order, METH_VARARGS, order_doc},
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
