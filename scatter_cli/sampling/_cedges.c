/* Edges by corner position: the same links as sharp.py's NumPy twin (_numpy_links).
 *
 * Corner slot s = 3 f + k of face f stands for the edge from its corner k to its corner
 * k + 1 mod 3. For the slots of the valid faces, links() writes first[s], the smallest
 * slot whose edge joins the same two positions, and next[s], the next such slot in
 * slot order (-1 after the last); the other slots get -1 in both. Positions are equal
 * when their coordinates are (-0.0 and 0.0 are one position), so a mesh whose corners are
 * repeated per face (STL, split glTF) links as its welded twin does. The links depend on
 * the positions and the face order only, never on how the vertices are numbered.
 *
 * Two radix sorts of small records, no hash table to probe: the used vertices by a hash of
 * their coordinates (within a run of equal hashes, equal coordinates get one position
 * number), then the slots by the lower position number of their edge (within a run, by
 * the upper one). The GIL is released while they run.
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

/* A slot of an edge: key (upper position << 32 | lower position), item its slot. */
typedef struct {
    uint64_t key;
    int64_t item;
} Record;

/* A used vertex: key a hash of its position, item its number, and its position (carried
 * along, so that telling positions apart reads no vertex array out of order). */
typedef struct {
    uint64_t key;
    int64_t item;
    double p[3];
} Vertex;

#define DIGIT 11
#define MASK ((1 << DIGIT) - 1)

/* Sort n records by the low ``bits`` bits of their key, stable (LSD radix, 11 bits a
 * pass), between the buffers a and b; returns the one that holds the result. */
#define RADIX_SORT(NAME, TYPE)                                                         \
    static TYPE *NAME(TYPE *a, TYPE *b, int64_t n, int bits)                           \
    {                                                                                  \
        int64_t count[MASK + 2];                                                       \
        for (int shift = 0; shift < bits; shift += DIGIT) {                            \
            memset(count, 0, sizeof count);                                            \
            for (int64_t i = 0; i < n; i++)                                            \
                count[((a[i].key >> shift) & MASK) + 1]++;                             \
            if (count[((a[0].key >> shift) & MASK) + 1] == n)                          \
                continue; /* one digit for all: the pass would move nothing */         \
            for (int d = 0; d <= MASK; d++)                                            \
                count[d + 1] += count[d];                                              \
            for (int64_t i = 0; i < n; i++)                                            \
                b[count[(a[i].key >> shift) & MASK]++] = a[i];                         \
            TYPE *t = a;                                                               \
            a = b, b = t;                                                              \
        }                                                                              \
        return a;                                                                      \
    }
RADIX_SORT(sort_records, Record)
RADIX_SORT(sort_vertices, Vertex)

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
 * coordinates; within a run of equal low bits, equal hashes and equal coordinates get one
 * number. Returns how many numbers there are. */
static int64_t number_positions(const double *v, const int64_t *faces, const npy_bool *valid, int64_t nf,
                                int64_t nv, int64_t *id, Vertex *a, Vertex *b, int64_t *rep)
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
            a[n++] = (Vertex){position_hash(v + 3 * i), i, {v[3 * i], v[3 * i + 1], v[3 * i + 2]}};
    int bits = bit_length((uint64_t)n) + 1;
    Vertex *r = sort_vertices(a, b, n, bits);
    for (int64_t t = 0; t < n;) {
        int64_t e = t + 1, reps = 0;
        while (e < n && low_bits(r[e].key ^ r[t].key, bits) == 0)
            e++;
        for (; t < e; t++) { /* a run: one position but for the rare other hash or collision */
            int64_t found = -1;
            for (int64_t q = 0; q < reps && found < 0; q++)
                if (r[rep[q]].key == r[t].key && same_position(r[rep[q]].p, r[t].p))
                    found = id[r[rep[q]].item];
            if (found < 0) {
                rep[reps++] = t;
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

/* The slots of the valid faces' edges as records (upper position << 32 | lower position,
 * slot), sorted by lower position; each run of one lower position then sorted by upper
 * position (slots in order for equal ones), so that each edge's slots come together in
 * slot order. */
static void link_slots(const int64_t *faces, const npy_bool *valid, int64_t nf, const int64_t *id,
                       int64_t positions, int64_t *first, int64_t *next, Record *a, Record *b)
{
    int64_t n = 0;
    for (int64_t s = 0; s < 3 * nf; s++)
        first[s] = next[s] = -1;
    for (int64_t f = 0; f < nf; f++) {
        if (!valid[f])
            continue;
        for (int c = 0; c < 3; c++) {
            uint64_t p = (uint64_t)id[faces[3 * f + c]], q = (uint64_t)id[faces[3 * f + (c + 1) % 3]];
            if (p != q) /* (no edge between one position and itself) */
                a[n++] = (Record){p < q ? q << 32 | p : p << 32 | q, 3 * f + c};
        }
    }
    int bits = bit_length((uint64_t)(positions > 0 ? positions - 1 : 0));
    Record *r = sort_records(a, b, n, bits);
    for (int64_t t = 0; t < n;) {
        int64_t e = t + 1;
        while (e < n && (uint32_t)r[e].key == (uint32_t)r[t].key)
            e++;
        if (e - t > 16)
            qsort(r + t, e - t, sizeof *r, by_upper_then_slot);
        else /* insertion sort: a run holds the few edges of one position */
            for (int64_t i = t + 1; i < e; i++)
                for (int64_t j = i; j > t && by_upper_then_slot(r + j - 1, r + j) > 0; j--) {
                    Record h = r[j];
                    r[j] = r[j - 1], r[j - 1] = h;
                }
        for (int64_t i = t; i < e;) { /* one edge: equal upper positions */
            int64_t k = i + 1;
            while (k < e && r[k].key == r[i].key)
                k++;
            for (int64_t j = i; j < k; j++) {
                first[r[j].item] = r[i].item;
                next[r[j].item] = j + 1 < k ? r[j + 1].item : -1;
            }
            i = k;
        }
        t = e;
    }
}

PyDoc_STRVAR(links_doc,
"links(vertices, faces, valid, first, next)\n\n"
"Edge links by corner position (see the file's comment): vertices (V, 3) float64, faces\n"
"(F, 3) int64, valid (F,) bool; first and next (3 F,) int64 are written. Raises\n"
"ValueError for a vertex index of a valid face out of range or more than 2^32 positions.");

static PyObject *links(PyObject *self, PyObject *args)
{
    PyObject *overts, *ofaces, *ovalid, *ofirst, *onext;
    PyArrayObject *verts_a, *faces_a, *valid_a, *first_a, *next_a;
    npy_intp nf;
    if (!PyArg_ParseTuple(args, "OOOOO", &overts, &ofaces, &ovalid, &ofirst, &onext) ||
        !get(overts, NPY_FLOAT64, -1, &verts_a, "vertices") || !get_rows(ofaces, NPY_INT64, 3, &faces_a, &nf, "faces") ||
        !get(ovalid, NPY_BOOL, nf, &valid_a, "valid") || !get(ofirst, NPY_INT64, 3 * nf, &first_a, "first") ||
        !get(onext, NPY_INT64, 3 * nf, &next_a, "next"))
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
    /* two buffers of n vertex records, also used as four of slot records (a Vertex is larger) */
    int64_t *id = malloc((nv > 0 ? nv : 1) * sizeof *id), *rep = malloc(n * sizeof *rep);
    Vertex *va = malloc(n * sizeof *va), *vb = malloc(n * sizeof *vb);
    int64_t positions = -1;
    if (id && rep && va && vb) {
        Py_BEGIN_ALLOW_THREADS
        positions = number_positions(v, faces, valid, nf, nv, id, va, vb, rep);
        if (positions <= (int64_t)UINT32_MAX)
            link_slots(faces, valid, nf, id, positions, PyArray_DATA(first_a), PyArray_DATA(next_a), (Record *)va,
                       (Record *)vb);
        Py_END_ALLOW_THREADS
    }
    free(id), free(rep), free(va), free(vb);
    if (positions < 0)
        return PyErr_NoMemory();
    if (positions > (int64_t)UINT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "more than 2^32 distinct positions");
        return NULL;
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"links", links, METH_VARARGS, links_doc},
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
