/* Edges by corner position: the same arrays as sharp.py's NumPy twin (_numpy_edges).
 *
 * Corner slot s = 3 f + k of face f stands for the edge from its corner k to its corner
 * k + 1 mod 3. The slots of the valid faces that join the same two positions form one
 * edge, named by its lowest slot (its head); edges() writes, in head order, each edge's
 * head, its second slot (-1 for a boundary edge) and its slot count, and the slots after
 * the second of the edges that have more (non-manifold ones), edge after edge, in slot
 * order: every edge but the pairs of faces whose normals are too close to be sharp (a
 * dot product at a limit or above), which are most of a mesh's edges. Positions are equal when their coordinates are (-0.0 and 0.0 are one position),
 * so a mesh whose corners are repeated per face (STL, split glTF) has the edges of its
 * welded twin, and nothing here depends on how the vertices are numbered.
 *
 * Three radix sorts of small records, no hash table to probe: the used vertices by a hash
 * of their coordinates (within a run of equal hashes, equal coordinates get one position
 * number), the slots by the lower position of their edge (within a run, by the upper one),
 * then the edges kept by their head. The GIL is released while they run.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include "_ckernel.h"
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
#define MASK ((1 << DIGIT) - 1)

/* Sort n records by the low ``bits`` bits of their key, stable (LSD radix, 11 bits a
 * pass), between the buffers a and b; returns the one that holds the result. */
static Record *radix_sort(Record *a, Record *b, int64_t n, int bits)
{
    int64_t count[MASK + 2];
    for (int shift = 0; shift < bits; shift += DIGIT) {
        memset(count, 0, sizeof count);
        for (int64_t i = 0; i < n; i++)
            count[((a[i].key >> shift) & MASK) + 1]++;
        if (count[((a[0].key >> shift) & MASK) + 1] == n)
            continue; /* one digit for all: the pass would move nothing */
        for (int d = 0; d <= MASK; d++)
            count[d + 1] += count[d];
        for (int64_t i = 0; i < n; i++)
            b[count[(a[i].key >> shift) & MASK]++] = a[i];
        Record *t = a;
        a = b, b = t;
    }
    return a;
}

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

/* Number the distinct positions of the vertices that valid faces use: id[v] for those
 * (the others keep -1). The vertices are sorted by the low bits of a hash of their
 * coordinates, their coordinates gathered in that order into xyz; within a run of equal
 * low bits, equal hashes and equal coordinates get one number. Returns how many numbers
 * there are. rep: scratch, two per vertex. */
static int64_t number_positions(const double *v, const int64_t *faces, const npy_bool *valid, int64_t nf,
                                int64_t nv, int64_t *id, Record *a, Record *b, double *xyz, int64_t *rep)
{
    int64_t n = 0, next_id = 0;
    for (int64_t i = 0; i < nv; i++)
        id[i] = -1;
    for (int64_t f = 0; f < nf; f++)
        if (valid[f])
            for (int k = 0; k < 3; k++)
                id[faces[3 * f + k]] = 0; /* used */
    for (int64_t i = 0; i < nv; i++)
        if (id[i] == 0)
            a[n++] = (Record){position_hash(v + 3 * i), i};
    int bits = bit_length((uint64_t)n) + 1;
    Record *r = radix_sort(a, b, n, bits);
    for (int64_t t = 0; t < n; t++) /* independent loads: they overlap */
        memcpy(xyz + 3 * t, v + 3 * r[t].item, 3 * sizeof *xyz);
    for (int64_t t = 0; t < n;) {
        int64_t e = t + 1, reps = 0;
        while (e < n && low_bits(r[e].key ^ r[t].key, bits) == 0)
            e++;
        for (; t < e; t++) { /* a run: one position but for the rare other hash or collision */
            int64_t found = -1; /* rep: the run's distinct positions, (record, number) pairs */
            for (int64_t q = 0; q < reps && found < 0; q++)
                if (r[rep[2 * q]].key == r[t].key && same_position(xyz + 3 * rep[2 * q], xyz + 3 * t))
                    found = rep[2 * q + 1];
            if (found < 0) {
                rep[2 * reps] = t, rep[2 * reps + 1] = next_id;
                reps++;
                found = next_id++;
            }
            id[r[t].item] = found;
        }
    }
    return next_id;
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

/* The edges of the valid faces' slots that are not pairs of faces whose unit normals
 * have a dot product of ``limit`` or more, in head order: head, second and count (E
 * each) and rest (the slots after the second of edges with more, edge after edge);
 * returns E and sets *rests. a and b: two buffers of 3 nf records; found: 3 nf int64,
 * start: 3 nf + 1. */
static int64_t find_edges(const int64_t *faces, const npy_bool *valid, int64_t nf, const int64_t *id,
                          int64_t positions, const double *normals, double limit, Record *a, Record *b,
                          int64_t *found, int64_t *start, int64_t *head, int64_t *second, int64_t *count,
                          int64_t *rest, int64_t *rests)
{
    int64_t n = 0;
    for (int64_t f = 0; f < nf; f++) {
        if (!valid[f])
            continue;
        for (int c = 0; c < 3; c++) {
            uint64_t p = (uint64_t)id[faces[3 * f + c]], q = (uint64_t)id[faces[3 * f + (c + 1) % 3]];
            if (p != q) /* (no edge between one position and itself) */
                a[n++] = (Record){p < q ? q << 32 | p : p << 32 | q, 3 * f + c};
        }
    }
    Record *r = radix_sort(a, b, n, bit_length((uint64_t)(positions > 0 ? positions - 1 : 0)));
    /* Group the slots of each edge, in the order of its lower and upper positions; an edge
     * kept is g: its slots found[start[g] .. start[g + 1] - 1], in slot order, and its
     * record (head, g) in the other buffer. */
    Record *edge = r == a ? b : a;
    int64_t edges = 0, kept = 0;
    for (int64_t t = 0; t < n;) {
        int64_t e = t + 1;
        while (e < n && (uint32_t)r[e].key == (uint32_t)r[t].key)
            e++;
        sort_run(r + t, e - t);
        for (int64_t i = t; i < e;) {
            int64_t k = i + 1;
            while (k < e && r[k].key == r[i].key)
                k++;
            if (k - i != 2 || !(dot(normals, r[i].item / 3, r[i + 1].item / 3) >= limit)) {
                start[edges] = kept;
                edge[edges] = (Record){(uint64_t)r[i].item, edges};
                for (int64_t j = i; j < k; j++)
                    found[kept++] = r[j].item;
                edges++;
            }
            i = k;
        }
        t = e;
    }
    start[edges] = kept;
    Record *sorted = radix_sort(edge, r, edges, bit_length((uint64_t)(3 * nf))); /* r: free now */
    int64_t m = 0;
    for (int64_t j = 0; j < edges; j++) {
        int64_t g = sorted[j].item, s0 = start[g], k = start[g + 1] - s0;
        head[j] = found[s0];
        second[j] = k > 1 ? found[s0 + 1] : -1;
        count[j] = k;
        for (int64_t i = 2; i < k; i++)
            rest[m++] = found[s0 + i];
    }
    *rests = m;
    return edges;
}

PyDoc_STRVAR(edges_doc,
"edges(vertices, faces, valid, normals, limit, head, second, count, rest) -> (E, R)\n\n"
"The edges of a triangle list by corner position (see the file's comment), but for the\n"
"pairs of faces whose unit normals (F, 3) float64 have a dot product of limit or more:\n"
"vertices (V, 3) float64, faces (F, 3) int64, valid (F,) bool; head, second, count and\n"
"rest (3 F,) int64 get the E edges' head, second slot and count, and the R slots after\n"
"the second of edges with more. Raises ValueError for a vertex index of a valid face out\n"
"of range or more than 2^32 distinct positions.");

static PyObject *edges(PyObject *self, PyObject *args)
{
    PyObject *overts, *ofaces, *ovalid, *onormals, *ohead, *osecond, *ocount, *orest;
    PyArrayObject *verts_a, *faces_a, *valid_a, *normals_a, *head_a, *second_a, *count_a, *rest_a;
    npy_intp nf;
    double limit;
    if (!PyArg_ParseTuple(args, "OOOOdOOOO", &overts, &ofaces, &ovalid, &onormals, &limit, &ohead, &osecond, &ocount,
                          &orest) ||
        !get(overts, NPY_FLOAT64, -1, &verts_a, "vertices") || !get_rows(ofaces, NPY_INT64, 3, &faces_a, &nf, "faces") ||
        !get(ovalid, NPY_BOOL, nf, &valid_a, "valid") || !get(onormals, NPY_FLOAT64, 3 * nf, &normals_a, "normals") ||
        !get(ohead, NPY_INT64, 3 * nf, &head_a, "head") ||
        !get(osecond, NPY_INT64, 3 * nf, &second_a, "second") || !get(ocount, NPY_INT64, 3 * nf, &count_a, "count") ||
        !get(orest, NPY_INT64, 3 * nf, &rest_a, "rest"))
        return NULL;
    const double *v = PyArray_DATA(verts_a);
    const int64_t *faces = PyArray_DATA(faces_a);
    const npy_bool *valid = PyArray_DATA(valid_a);
    int64_t nv = PyArray_SIZE(verts_a) / 3;
    uint64_t bad = 0;
    for (npy_intp f = 0; f < nf; f++)
        if (valid[f])
            for (int k = 0; k < 3; k++)
                bad |= (uint64_t)faces[3 * f + k] >= (uint64_t)nv;
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "face indices out of range");
        return NULL;
    }
    int64_t n = (3 * (int64_t)nf > nv ? 3 * (int64_t)nf : nv) + 1;
    int64_t *id = malloc((nv > 0 ? nv : 1) * sizeof *id), *rep = malloc(2 * n * sizeof *rep),
            *start = malloc((n + 1) * sizeof *start);
    Record *ra = malloc(n * sizeof *ra), *rb = malloc(n * sizeof *rb);
    double *xyz = malloc(3 * n * sizeof *xyz);
    int64_t positions = -1, found = 0, rests = 0;
    if (id && rep && start && ra && rb && xyz) {
        Py_BEGIN_ALLOW_THREADS
        positions = number_positions(v, faces, valid, nf, nv, id, ra, rb, xyz, rep);
        if (positions <= (int64_t)UINT32_MAX)
            found = find_edges(faces, valid, nf, id, positions, PyArray_DATA(normals_a), limit, ra, rb, rep, start,
                               PyArray_DATA(head_a),
                               PyArray_DATA(second_a), PyArray_DATA(count_a), PyArray_DATA(rest_a), &rests);
        Py_END_ALLOW_THREADS
    }
    free(id), free(rep), free(start), free(ra), free(rb), free(xyz);
    if (positions < 0)
        return PyErr_NoMemory();
    if (positions > (int64_t)UINT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "more than 2^32 distinct positions");
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
