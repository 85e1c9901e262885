/* Edges by corner position: the same arrays as sharp.py's NumPy twin (_numpy_edge_slots).
 *
 * Corner slot s = 3 f + k of face f stands for the edge from its corner k to its corner
 * k + 1 mod 3. The slots of the valid faces that join the same two positions form one
 * edge, named by its lowest slot (its head); edges() writes, in head order, each edge's
 * head, its second slot (-1 for a boundary edge) and its slot count, and the slots after
 * the second of the edges that have more (non-manifold ones), edge after edge, in slot
 * order: every edge but the pairs of faces whose normals are too close to be sharp (a
 * dot product at a limit or above), which are most of a mesh's edges. Positions are equal
 * when their coordinates are (-0.0 and 0.0 are one position), so a mesh whose corners are
 * repeated per face (STL, split glTF) has the edges of its welded twin, and nothing here
 * depends on how the vertices are numbered.
 *
 * Radix sorts of small records, no hash table to probe: the used vertices by a hash of
 * their coordinates (within a run of equal hashes, equal coordinates get one position
 * number: the place of the first of them in that order), the slots by the lower position
 * of their edge (within a run, by the upper one), then the edges kept by their head.
 * Each step is cut into fixed shares of its items, many a thread (_cthreads.h's pieces),
 * and every share writes where its place in the whole says, so the result never depends
 * on the thread count or on timing. The GIL is released while they run.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include "_ckernel.h"
#include "_cthreads.h"
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

static inline uint64_t mix64(uint64_t z)
{
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

/* The bits of a coordinate, -0.0 counted as 0.0. */
static inline uint64_t bits_of(double x)
{
    uint64_t w;
    x += 0.0;
    memcpy(&w, &x, sizeof w);
    return w;
}

static inline uint64_t position_hash(const double *p)
{
    return mix64(bits_of(p[0]) ^ mix64(bits_of(p[1]) ^ mix64(bits_of(p[2]))));
}

static inline int same_position(const double *p, const double *q)
{
    return bits_of(p[0]) == bits_of(q[0]) && bits_of(p[1]) == bits_of(q[1]) && bits_of(p[2]) == bits_of(q[2]);
}

typedef struct {
    uint64_t key;
    int64_t item;
} Record;

#define DIGIT 11
#define BUCKETS (1 << DIGIT)
#define SHARE_ITEMS 8192 /* items a share at least: its BUCKETS counters are worth their cost */

static int bit_length(uint64_t x)
{
    int bits = 0;
    for (; x; x >>= 1)
        bits++;
    return bits;
}

static inline uint64_t low_bits(uint64_t x, int bits)
{
    return bits >= 64 ? x : x & ((UINT64_C(1) << bits) - 1);
}

/* ---- a stable radix sort, in shares of the records ---- */

typedef struct {
    Record *from, *to;
    int64_t n;
    int shift, shares;
    int64_t *count; /* BUCKETS counters per share */
} Pass;

static void count_digits(void *ctx, int k, int shares)
{
    Pass *p = ctx;
    int64_t i0, i1, *count = p->count + (int64_t)k * BUCKETS;
    share(p->n, k, shares, &i0, &i1);
    memset(count, 0, BUCKETS * sizeof *count);
    for (int64_t i = i0; i < i1; i++)
        count[(p->from[i].key >> p->shift) & (BUCKETS - 1)]++;
}

static void move_records(void *ctx, int k, int shares)
{
    Pass *p = ctx;
    int64_t i0, i1, *at = p->count + (int64_t)k * BUCKETS;
    share(p->n, k, shares, &i0, &i1);
    for (int64_t i = i0; i < i1; i++)
        p->to[at[(p->from[i].key >> p->shift) & (BUCKETS - 1)]++] = p->from[i];
}

/* Sort n records by the low ``bits`` bits of their key, stable (LSD radix, 11 bits a
 * pass), between the buffers a and b, in ``shares`` shares on ``threads`` threads; returns
 * the one that holds the result. count: BUCKETS counters per share. */
static Record *radix_sort(Record *a, Record *b, int64_t n, int bits, int shares, int threads, int64_t *count)
{
    for (int shift = 0; shift < bits; shift += DIGIT) {
        Pass p = {a, b, n, shift, shares, count};
        in_pieces(shares, threads, count_digits, &p);
        int64_t total = 0, largest = 0;
        for (int d = 0; d < BUCKETS; d++) /* where each share's records of each digit go */
            for (int k = 0; k < shares; k++) {
                int64_t c = count[(int64_t)k * BUCKETS + d];
                count[(int64_t)k * BUCKETS + d] = total;
                total += c;
                largest = c > largest ? c : largest;
            }
        if (largest == n) /* one digit for all: the pass would move nothing */
            continue;
        in_pieces(shares, threads, move_records, &p);
        Record *t = a;
        a = b, b = t;
    }
    return a;
}

/* ---- positions ---- */

typedef struct {
    const double *v;
    const int64_t *faces;
    const npy_bool *valid;
    int64_t nf, nv, n;
    unsigned char *used;
    int64_t *id, *offset; /* offset: the first record of each share of vertices */
    Record *r;
    double *xyz;
    int bits;
} Positions;

static void mark_used(void *ctx, int k, int shares)
{
    Positions *c = ctx;
    int64_t f0, f1;
    share(c->nf, k, shares, &f0, &f1);
    for (int64_t f = f0; f < f1; f++)
        if (c->valid[f])
            for (int j = 0; j < 3; j++)
                __atomic_store_n(&c->used[c->faces[3 * f + j]], 1, __ATOMIC_RELAXED);
}

static void count_used(void *ctx, int k, int shares)
{
    Positions *c = ctx;
    int64_t i0, i1, n = 0;
    share(c->nv, k, shares, &i0, &i1);
    for (int64_t i = i0; i < i1; i++)
        n += c->used[i];
    c->offset[k] = n;
}

static void hash_used(void *ctx, int k, int shares)
{
    Positions *c = ctx;
    int64_t i0, i1, at = c->offset[k];
    share(c->nv, k, shares, &i0, &i1);
    for (int64_t i = i0; i < i1; i++) {
        c->id[i] = -1;
        if (c->used[i])
            c->r[at++] = (Record){position_hash(c->v + 3 * i), i};
    }
}

static void gather_positions(void *ctx, int k, int shares)
{
    Positions *c = ctx;
    int64_t t0, t1;
    share(c->n, k, shares, &t0, &t1);
    for (int64_t t = t0; t < t1; t++) /* independent loads: they overlap */
        memcpy(c->xyz + 3 * t, c->v + 3 * c->r[t].item, 3 * sizeof *c->xyz);
}

/* The first record of the run (equal low bits of the hash) that holds record t or
 * follows it. */
static inline int64_t run_start(const Positions *c, int64_t t)
{
    while (t > 0 && t < c->n && low_bits(c->r[t].key ^ c->r[t - 1].key, c->bits) == 0)
        t++;
    return t;
}

static void number_runs(void *ctx, int k, int shares)
{
    Positions *c = ctx;
    int64_t t0, t1;
    share(c->n, k, shares, &t0, &t1);
    t0 = run_start(c, t0), t1 = run_start(c, t1);
    for (int64_t t = t0; t < t1;) {
        int64_t e = t + 1;
        while (e < c->n && low_bits(c->r[e].key ^ c->r[t].key, c->bits) == 0)
            e++;
        for (int64_t i = t; i < e; i++) { /* a run: one position but for the rare other hash or collision */
            int64_t first = i;
            for (int64_t q = t; q < i && first == i; q++)
                if (c->r[q].key == c->r[i].key && same_position(c->xyz + 3 * q, c->xyz + 3 * i))
                    first = c->id[c->r[q].item];
            c->id[c->r[i].item] = first;
        }
        t = e;
    }
}

/* Number the distinct positions of the vertices that valid faces use: id[v] for those
 * (the others -1), each the place in the hash order of the first vertex at its position.
 * Returns the count of used vertices (the numbers are below it). a and b: buffers of nv
 * records; xyz: 3 nv doubles; used: nv bytes; offset: one per share; count: BUCKETS
 * counters per share. */
static int64_t number_positions(Positions *c, Record *a, Record *b, int shares, int threads, int64_t *count)
{
    memset(c->used, 0, c->nv);
    in_pieces(shares, threads, mark_used, c);
    in_pieces(shares, threads, count_used, c);
    int64_t n = 0;
    for (int k = 0; k < shares; k++) {
        int64_t m = c->offset[k];
        c->offset[k] = n;
        n += m;
    }
    c->r = a;
    in_pieces(shares, threads, hash_used, c);
    c->n = n;
    c->bits = bit_length((uint64_t)n) + 1;
    c->r = radix_sort(a, b, n, c->bits, shares, threads, count);
    in_pieces(shares, threads, gather_positions, c);
    in_pieces(shares, threads, number_runs, c);
    return n;
}

/* ---- edges ---- */

typedef struct {
    const int64_t *faces, *id;
    const npy_bool *valid;
    const double *normals;
    double limit;
    int64_t nf, n;
    int64_t *offset; /* per share: its first record */
    int64_t *kept; /* per share: how many edges it kept (in its own place) */
    Record *r, *edge; /* the slot records; the edges kept, (head, their number) */
    int64_t *found, *place, *count; /* slots of the edges kept; an edge's first slot in found, its slot count */
} Edges;

static inline int edge_of(const Edges *c, int64_t f, int j, uint64_t *key)
{
    uint64_t p = (uint64_t)c->id[c->faces[3 * f + j]], q = (uint64_t)c->id[c->faces[3 * f + (j + 1) % 3]];
    *key = p < q ? q << 32 | p : p << 32 | q;
    return p != q; /* (no edge between one position and itself) */
}

static void count_slots(void *ctx, int k, int shares)
{
    Edges *c = ctx;
    int64_t f0, f1, n = 0;
    uint64_t key;
    share(c->nf, k, shares, &f0, &f1);
    for (int64_t f = f0; f < f1; f++)
        if (c->valid[f])
            for (int j = 0; j < 3; j++)
                n += edge_of(c, f, j, &key);
    c->offset[k] = n;
}

static void fill_slots(void *ctx, int k, int shares)
{
    Edges *c = ctx;
    int64_t f0, f1, at = c->offset[k];
    uint64_t key;
    share(c->nf, k, shares, &f0, &f1);
    for (int64_t f = f0; f < f1; f++)
        if (c->valid[f])
            for (int j = 0; j < 3; j++)
                if (edge_of(c, f, j, &key))
                    c->r[at++] = (Record){key, 3 * f + j};
}

static int by_upper_then_slot(const void *x, const void *y)
{
    const Record *a = x, *b = y;
    uint64_t ua = a->key >> 32, ub = b->key >> 32;
    return ua != ub ? (ua < ub ? -1 : 1) : (a->item < b->item ? -1 : a->item > b->item);
}

/* Sort a run of slot records by upper position, slots in order for equal ones. */
static void sort_run(Record *r, int64_t n)
{
    if (n > 16) {
        qsort(r, n, sizeof *r, by_upper_then_slot);
        return;
    }
    for (int64_t i = 1; i < n; i++) /* insertion sort: a run holds the few edges of one position */
        for (int64_t j = i; j > 0 && by_upper_then_slot(r + j - 1, r + j) > 0; j--) {
            Record h = r[j];
            r[j] = r[j - 1], r[j - 1] = h;
        }
}

static inline double dot(const double *n, int64_t f, int64_t g)
{
    const double *a = n + 3 * f, *b = n + 3 * g;
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* The first record of the run (one lower position) that holds record t or follows it. */
static inline int64_t lower_run_start(const Edges *c, int64_t t)
{
    while (t > 0 && t < c->n && (uint32_t)c->r[t].key == (uint32_t)c->r[t - 1].key)
        t++;
    return t;
}

/* One share of the runs: each run sorted by upper position, the edges it keeps
 * written from t0 on, t0 the share's first record (there is room: an edge has a slot at
 * least): their records in edge[], their first slot's place in found[] in place[], their
 * slot count in count[]. */
static void keep_edges(void *ctx, int k, int shares)
{
    Edges *c = ctx;
    int64_t t0, t1;
    share(c->n, k, shares, &t0, &t1);
    t0 = lower_run_start(c, t0), t1 = lower_run_start(c, t1);
    int64_t edges = t0, slots = t0;
    for (int64_t t = t0; t < t1;) {
        int64_t e = t + 1;
        while (e < t1 && (uint32_t)c->r[e].key == (uint32_t)c->r[t].key)
            e++;
        sort_run(c->r + t, e - t);
        for (int64_t i = t; i < e;) {
            int64_t m = i + 1;
            while (m < e && c->r[m].key == c->r[i].key)
                m++;
            if (m - i != 2 || !(dot(c->normals, c->r[i].item / 3, c->r[i + 1].item / 3) >= c->limit)) {
                c->edge[edges] = (Record){(uint64_t)c->r[i].item, edges};
                c->place[edges] = slots, c->count[edges] = m - i;
                edges++;
                for (int64_t j = i; j < m; j++)
                    c->found[slots++] = c->r[j].item;
            }
            i = m;
        }
        t = e;
    }
    c->offset[k] = t0, c->kept[k] = edges - t0;
}

/* The edges kept, from every share's place, into one list in head order: head, second,
 * count and rest (the slots after the second, edge after edge); returns how many and
 * sets *rests. */
static int64_t list_edges(Edges *c, int shares, Record *scratch, int64_t *counters, int64_t *head,
                          int64_t *second, int64_t *count, int64_t *rest, int64_t *rests)
{
    int64_t edges = 0;
    for (int k = 0; k < shares; k++) /* every share's edges after the ones before (never ahead) */
        for (int64_t j = 0; j < c->kept[k]; j++, edges++) {
            int64_t at = c->offset[k] + j;
            c->edge[edges] = (Record){c->edge[at].key, edges};
            c->place[edges] = c->place[at], c->count[edges] = c->count[at];
        }
    Record *sorted = radix_sort(c->edge, scratch, edges, bit_length((uint64_t)(3 * c->nf)), 1, 1, counters);
    int64_t m = 0;
    for (int64_t j = 0; j < edges; j++) {
        int64_t g = sorted[j].item, s0 = c->place[g], n = c->count[g];
        head[j] = c->found[s0];
        second[j] = n > 1 ? c->found[s0 + 1] : -1;
        count[j] = n;
        for (int64_t i = 2; i < n; i++)
            rest[m++] = c->found[s0 + i];
    }
    *rests = m;
    return edges;
}

/* The edges (see the top of the file) into head, second, count, rest; returns E, sets
 * *rests; -1 when out of memory, -2 when there are more than 2^32 used vertices. */
static int64_t find_edges(const double *v, const int64_t *faces, const npy_bool *valid, int64_t nf, int64_t nv,
                          const double *normals, double limit, int threads, int64_t *head, int64_t *second,
                          int64_t *count, int64_t *rest, int64_t *rests)
{
    int64_t n = (3 * nf > nv ? 3 * nf : nv) + 1, result = -1;
    int shares = pieces_for(n, SHARE_ITEMS, threads);
    int64_t *id = malloc((nv + 1) * sizeof *id), *offset = malloc(shares * sizeof *offset),
            *kept = malloc(shares * sizeof *kept), *counters = malloc((int64_t)shares * BUCKETS * sizeof *counters),
            *found = malloc(n * sizeof *found), *place = malloc(n * sizeof *place), *cnt = malloc(n * sizeof *cnt);
    unsigned char *used = malloc(nv + 1);
    Record *a = malloc(n * sizeof *a), *b = malloc(n * sizeof *b);
    double *xyz = malloc(3 * (nv + 1) * sizeof *xyz);
    if (id && offset && kept && counters && found && place && cnt && used && a && b && xyz) {
        Positions p = {v, faces, valid, nf, nv, 0, used, id, offset, NULL, xyz, 0};
        int64_t positions = number_positions(&p, a, b, shares, threads, counters);
        if (positions > (int64_t)UINT32_MAX) {
            result = -2;
        } else {
            Edges e = {faces, id, valid, normals, limit, nf, 0, offset, kept, a, NULL, found, place, cnt};
            in_pieces(shares, threads, count_slots, &e);
            for (int k = 0; k < shares; k++) {
                int64_t m = offset[k];
                offset[k] = e.n;
                e.n += m;
            }
            in_pieces(shares, threads, fill_slots, &e);
            e.r = radix_sort(a, b, e.n, bit_length((uint64_t)(positions > 0 ? positions - 1 : 0)), shares, threads,
                             counters);
            e.edge = e.r == a ? b : a;
            in_pieces(shares, threads, keep_edges, &e);
            result = list_edges(&e, shares, e.r, counters, head, second, count, rest, rests);
        }
    }
    free(id), free(offset), free(kept), free(counters), free(found), free(place), free(cnt), free(used), free(a),
        free(b), free(xyz);
    return result;
}

PyDoc_STRVAR(edges_doc,
"edges(vertices, faces, valid, normals, limit, threads, head, second, count, rest) -> (E, R)\n\n"
"The edges of a triangle list by corner position (see the file's comment), but for the\n"
"pairs of faces whose unit normals (F, 3) float64 have a dot product of limit or more:\n"
"vertices (V, 3) float64, faces (F, 3) int64, valid (F,) bool; head, second, count and\n"
"rest (3 F,) int64 get the E edges' head, second slot and count, and the R slots after\n"
"the second of edges with more; on ``threads`` threads. Raises ValueError for a vertex\n"
"index of a valid face out of range or more than 2^32 used vertices.");

static PyObject *edges(PyObject *self, PyObject *args)
{
    PyObject *overts, *ofaces, *ovalid, *onormals, *ohead, *osecond, *ocount, *orest;
    PyArrayObject *verts_a, *faces_a, *valid_a, *normals_a, *head_a, *second_a, *count_a, *rest_a;
    npy_intp nf;
    double limit;
    int threads;
    if (!PyArg_ParseTuple(args, "OOOOdiOOOO", &overts, &ofaces, &ovalid, &onormals, &limit, &threads, &ohead,
                          &osecond, &ocount, &orest) ||
        !get(overts, NPY_FLOAT64, -1, &verts_a, "vertices") || !get_rows(ofaces, NPY_INT64, 3, &faces_a, &nf, "faces") ||
        !get(ovalid, NPY_BOOL, nf, &valid_a, "valid") || !get(onormals, NPY_FLOAT64, 3 * nf, &normals_a, "normals") ||
        !get(ohead, NPY_INT64, 3 * nf, &head_a, "head") || !get(osecond, NPY_INT64, 3 * nf, &second_a, "second") ||
        !get(ocount, NPY_INT64, 3 * nf, &count_a, "count") || !get(orest, NPY_INT64, 3 * nf, &rest_a, "rest"))
        return NULL;
    const int64_t *faces = PyArray_DATA(faces_a);
    const npy_bool *valid = PyArray_DATA(valid_a);
    int64_t nv = PyArray_SIZE(verts_a) / 3, rests = 0, found;
    uint64_t bad = 0;
    for (npy_intp f = 0; f < nf; f++)
        if (valid[f])
            for (int k = 0; k < 3; k++)
                bad |= (uint64_t)faces[3 * f + k] >= (uint64_t)nv;
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "face indices out of range");
        return NULL;
    }
    threads = threads < 1 ? 1 : threads;
    Py_BEGIN_ALLOW_THREADS
    found = find_edges(PyArray_DATA(verts_a), faces, valid, nf, nv, PyArray_DATA(normals_a), limit, threads,
                       PyArray_DATA(head_a), PyArray_DATA(second_a), PyArray_DATA(count_a), PyArray_DATA(rest_a),
                       &rests);
    Py_END_ALLOW_THREADS
    if (found == -1)
        return PyErr_NoMemory();
    if (found == -2) {
        PyErr_SetString(PyExc_ValueError, "more than 2^32 used vertices");
        return NULL;
    }
    return Py_BuildValue("LL", (long long)found, (long long)rests);
}

static PyMethodDef methods[] = {
    {"edges", edges, METH_VARARGS, edges_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cedges", "Edges by corner position (see sharp.py).", -1, methods,
};

PyMODINIT_FUNC PyInit__cedges(void)
{
    import_array();
    return PyModule_Create(&module);
}
