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
 * Radix sorts of small records, no hash table to probe: the slots by the low bits of a
 * key of their edge, hashed from its two end positions' coordinates, the same either way
 * round; within a run of equal low bits (an edge's slots, and now and then another
 * edge's), the slots of equal keys whose end positions are equal form an edge (so a
 * collision of keys never joins two edges); then the edges kept by their head. Each step
 * is cut into fixed shares of its items, many a thread (_cthreads.h's pieces), and every
 * share writes where its place in the whole says, so the result never depends
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

/* ---- slots ---- */

/* Face blocks: for each face, the bits of its three corners' coordinates (-0.0 as 0.0)
 * and its unit normal's, 12 words: what keep_edges() reads of a slot's face, in one place. */
#define BLOCK 12

/* Whether slots s and t join the same two positions (either way round). */
static inline int same_edge(const uint64_t *blocks, int64_t s, int64_t t)
{
    const uint64_t *a = blocks + BLOCK * (s / 3), *b = blocks + BLOCK * (t / 3);
    const uint64_t *p = a + 3 * (s % 3), *q = a + 3 * ((s + 1) % 3), *p2 = b + 3 * (t % 3), *q2 = b + 3 * ((t + 1) % 3);
    return (p[0] == p2[0] && p[1] == p2[1] && p[2] == p2[2] && q[0] == q2[0] && q[1] == q2[1] && q[2] == q2[2]) ||
           (p[0] == q2[0] && p[1] == q2[1] && p[2] == q2[2] && q[0] == p2[0] && q[1] == p2[1] && q[2] == p2[2]);
}

/* The dot product of the unit normals of slot s's and slot t's faces. */
static inline double dot(const uint64_t *blocks, int64_t s, int64_t t)
{
    double a[3], b[3];
    memcpy(a, blocks + BLOCK * (s / 3) + 9, sizeof a), memcpy(b, blocks + BLOCK * (t / 3) + 9, sizeof b);
    return a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
}

/* The coordinates' bits of position p (-0.0 as 0.0) into w. */
static inline void position_bits(const double *p, uint64_t *w)
{
    w[0] = bits_of(p[0]), w[1] = bits_of(p[1]), w[2] = bits_of(p[2]);
}

/* The key of the edge between positions hashed a and b: the same either way round. */
static inline uint64_t edge_key(uint64_t a, uint64_t b)
{
    uint64_t lo = a < b ? a : b, hi = a < b ? b : a;
    return mix64(lo ^ mix64(hi ^ 0x9E3779B97F4A7C15ULL));
}

typedef struct {
    const double *v;
    const int64_t *faces;
    const npy_bool *valid;
    const double *normals;
    double limit;
    int64_t nf, n;
    int bits;
    int64_t *offset; /* per share: its first record */
    int64_t *kept; /* per share: how many edges it kept (in its own place) */
    int64_t *bounds; /* share k keeps the edges of records bounds[k] .. bounds[k + 1] - 1: whole runs */
    Record *r, *edge; /* the slot records (edge key, slot); the edges kept, (head, their number) */
    int64_t *found, *place, *count; /* slots of the edges kept; an edge's first slot in found, its slot count */
    uint64_t *blocks; /* BLOCK words a face */
} Edges;

static void count_slots(void *ctx, int k, int shares)
{
    Edges *c = ctx;
    int64_t f0, f1, n = 0;
    share(c->nf, k, shares, &f0, &f1);
    for (int64_t f = f0; f < f1; f++)
        if (c->valid[f]) {
            const double *p[3] = {c->v + 3 * c->faces[3 * f], c->v + 3 * c->faces[3 * f + 1], c->v + 3 * c->faces[3 * f + 2]};
            for (int j = 0; j < 3; j++) /* (no edge between one position and itself) */
                n += !same_position(p[j], p[(j + 1) % 3]);
        }
    c->offset[k] = n;
}

static void fill_slots(void *ctx, int k, int shares)
{
    Edges *c = ctx;
    int64_t f0, f1, at = c->offset[k];
    share(c->nf, k, shares, &f0, &f1);
    for (int64_t f = f0; f < f1; f++)
        if (c->valid[f]) {
            uint64_t *w = c->blocks + BLOCK * f, h[3];
            for (int j = 0; j < 3; j++) {
                position_bits(c->v + 3 * c->faces[3 * f + j], w + 3 * j);
                h[j] = mix64(w[3 * j] ^ mix64(w[3 * j + 1] ^ mix64(w[3 * j + 2])));
            }
            memcpy(w + 9, c->normals + 3 * f, 3 * sizeof *w);
            for (int j = 0; j < 3; j++) {
                const uint64_t *p = w + 3 * j, *q = w + 3 * ((j + 1) % 3);
                if (p[0] != q[0] || p[1] != q[1] || p[2] != q[2]) /* (no edge between one position and itself) */
                    c->r[at++] = (Record){edge_key(h[j], h[(j + 1) % 3]), 3 * f + j};
            }
        }
}

static int by_key_then_slot(const void *x, const void *y)
{
    const Record *a = x, *b = y;
    return a->key != b->key ? (a->key < b->key ? -1 : 1) : (a->item < b->item ? -1 : a->item > b->item);
}

/* Sort a run of slot records by key, slots in order for equal ones. */
static void sort_run(Record *r, int64_t n)
{
    if (n > 16) {
        qsort(r, n, sizeof *r, by_key_then_slot);
        return;
    }
    for (int64_t i = 1; i < n; i++) /* insertion sort: a run holds an edge's slots or two */
        for (int64_t j = i; j > 0 && by_key_then_slot(r + j - 1, r + j) > 0; j--) {
            Record h = r[j];
            r[j] = r[j - 1], r[j - 1] = h;
        }
}

/* The first record of the run (equal low bits of the key) that holds record t or follows it. */
static inline int64_t run_start(const Edges *c, int64_t t)
{
    while (t > 0 && t < c->n && low_bits(c->r[t].key ^ c->r[t - 1].key, c->bits) == 0)
        t++;
    return t;
}

/* The edges of records [i, m), all of one key, in order of their first slot, each one's
 * slots in order: written from edges and slots on (see keep_edges); returns the new edge
 * count and sets *slots. Records of an edge already written get the key's complement. */
static int64_t keep_key(Edges *c, int64_t i, int64_t m, int64_t edges, int64_t *slots)
{
    uint64_t key = c->r[i].key;
    for (int64_t lead = i; lead < m; lead++) {
        if (c->r[lead].key != key) /* (taken by an edge before) */
            continue;
        int64_t first = *slots, s = c->r[lead].item;
        c->found[(*slots)++] = s;
        for (int64_t j = lead + 1; j < m; j++) /* one edge but for a collision of the 64-bit keys */
            if (c->r[j].key == key && same_edge(c->blocks, s, c->r[j].item)) {
                c->found[(*slots)++] = c->r[j].item;
                c->r[j].key = ~key;
            }
        int64_t n = *slots - first;
        if (n == 2 && dot(c->blocks, s, c->found[first + 1]) >= c->limit) {
            *slots = first; /* two faces too close to flat to be sharp */
            continue;
        }
        c->edge[edges] = (Record){(uint64_t)s, edges};
        c->place[edges] = first, c->count[edges] = n;
        edges++;
    }
    return edges;
}

/* Records ahead of the one keep_edges() reads whose memory it asks for early: the slots
 * of an edge lie far apart, and reading their corners one after the other would wait on
 * memory at every step. */
#define AHEAD 16

static inline void ask(const Edges *c, int64_t s)
{
    __builtin_prefetch(c->blocks + BLOCK * (s / 3));
    __builtin_prefetch(c->blocks + BLOCK * (s / 3) + BLOCK - 1);
}

/* One share of the runs (cut before any share starts: keep_key() marks keys), each run
 * sorted by key; the edges it keeps are written from t0 on, t0 the share's first record
 * (there is room: an edge has a slot at least): their records in edge[], their first
 * slot's place in found[] in place[], their slot count in count[]. */
static void keep_edges(void *ctx, int k, int shares)
{
    Edges *c = ctx;
    int64_t t0 = c->bounds[k], t1 = c->bounds[k + 1];
    (void)shares;
    int64_t edges = t0, slots = t0, asked = t0;
    for (int64_t t = t0; t < t1;) {
        int64_t e = t + 1;
        while (e < t1 && low_bits(c->r[e].key ^ c->r[t].key, c->bits) == 0)
            e++;
        for (; asked < t1 && asked < e + AHEAD; asked++)
            ask(c, c->r[asked].item);
        if (e - t > 2)
            sort_run(c->r + t, e - t);
        for (int64_t i = t; i < e;) {
            int64_t m = i + 1;
            while (m < e && c->r[m].key == c->r[i].key)
                m++;
            edges = keep_key(c, i, m, edges, &slots);
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
 * *rests; -1 when out of memory. */
static int64_t find_edges(const double *v, const int64_t *faces, const npy_bool *valid, int64_t nf,
                          const double *normals, double limit, int threads, int64_t *head, int64_t *second,
                          int64_t *count, int64_t *rest, int64_t *rests)
{
    int64_t n = 3 * nf + 1, result = -1;
    int shares = pieces_for(n, SHARE_ITEMS, threads);
    int64_t *offset = malloc(shares * sizeof *offset), *kept = malloc(shares * sizeof *kept),
            *bounds = malloc((shares + 1) * sizeof *bounds),
            *counters = malloc((int64_t)shares * BUCKETS * sizeof *counters), *found = large_alloc(n * sizeof *found),
            *place = large_alloc(n * sizeof *place), *cnt = large_alloc(n * sizeof *cnt);
    Record *a = large_alloc(n * sizeof *a), *b = large_alloc(n * sizeof *b);
    uint64_t *blocks = large_alloc(BLOCK * (nf + 1) * sizeof *blocks);
    if (offset && kept && bounds && counters && found && place && cnt && a && b && blocks) {
        Edges e = {v, faces, valid, normals, limit, nf, 0, 0, offset, kept, bounds, a, NULL, found, place, cnt, blocks};
        in_pieces(shares, threads, count_slots, &e);
        for (int k = 0; k < shares; k++) {
            int64_t m = offset[k];
            offset[k] = e.n;
            e.n += m;
        }
        in_pieces(shares, threads, fill_slots, &e);
        e.bits = bit_length((uint64_t)e.n) + 1; /* runs of equal low bits: an edge's slots, rarely more */
        e.r = radix_sort(a, b, e.n, e.bits, shares, threads, counters);
        e.edge = e.r == a ? b : a;
        for (int k = 0; k <= shares; k++)
            bounds[k] = run_start(&e, (int64_t)((__int128)e.n * k / shares));
        in_pieces(shares, threads, keep_edges, &e);
        result = list_edges(&e, shares, e.r, counters, head, second, count, rest, rests);
    }
    free(offset), free(kept), free(bounds), free(counters), free(found), free(place), free(cnt), free(a), free(b), free(blocks);
    return result;
}

PyDoc_STRVAR(edges_doc,
"edges(vertices, faces, valid, normals, limit, threads, head, second, count, rest) -> (E, R)\n\n"
"The edges of a triangle list by corner position (see the file's comment), but for the\n"
"pairs of faces whose unit normals (F, 3) float64 have a dot product of limit or more:\n"
"vertices (V, 3) float64, faces (F, 3) int64, valid (F,) bool; head, second, count and\n"
"rest (3 F,) int64 get the E edges' head, second slot and count, and the R slots after\n"
"the second of edges with more; on ``threads`` threads. Raises ValueError for a vertex\n"
"index of a valid face out of range.");

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
    found = find_edges(PyArray_DATA(verts_a), faces, valid, nf, PyArray_DATA(normals_a), limit, threads,
                       PyArray_DATA(head_a), PyArray_DATA(second_a), PyArray_DATA(count_a), PyArray_DATA(rest_a),
                       &rests);
    Py_END_ALLOW_THREADS
    if (found == -1)
        return PyErr_NoMemory();
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
