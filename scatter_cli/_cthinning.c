/* Compiled pair graph and greedy thinning: the same results as thinning.py's NumPy path.
 *
 * grid() sorts points by cell (side >= reach). pairs() and greedy() visit the cells in key
 * order and test each cell's points against the 27 cells around it, which nine cursors
 * moving forward find in the sorted cell list (no hashing, little random access).
 * greedy() takes a maximal independent set of the pairs shorter than a radius, least
 * crowded first; it keeps each point's neighbours as a bit mask over the 27 cells (about
 * 24 bytes a point) rather than a pair list (about 280), because memory is time: on this
 * host every freshly touched gigabyte costs about a second. Distances and crowding are computed with
 * the same float64 operations as the NumPy code (built with -ffp-contract=off) and
 * crowding is a sum of integers, so neither the order pairs are found in nor the path
 * changes a result.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <pthread.h>
#include <stdio.h>

#define BITS 21
#define MAX_CELLS ((1 << BITS) - 8) /* thinning._MAX_CELLS */
#define CROWD_SCALE 65536.0          /* thinning._CROWD_SCALE */

static uint64_t pack(int64_t x, int64_t y, int64_t z)
{
    return ((uint64_t)x << (2 * BITS)) | ((uint64_t)y << BITS) | (uint64_t)z;
}

static void free_buffer(PyObject *capsule)
{
    free(PyCapsule_GetPointer(capsule, NULL));
}

/* A 1-D array over ``data`` (from malloc), which it frees when it goes. */
static PyObject *owned_array(int type, npy_intp n, void *data)
{
    npy_intp dims[1] = {n};
    PyObject *capsule = PyCapsule_New(data, NULL, free_buffer);
    if (!capsule) {
        free(data);
        return NULL;
    }
    PyObject *arr = PyArray_SimpleNewFromData(1, dims, type, data);
    if (!arr) {
        Py_DECREF(capsule);
        return NULL;
    }
    if (PyArray_SetBaseObject((PyArrayObject *)arr, capsule) < 0) { /* steals capsule */
        Py_DECREF(arr);
        return NULL;
    }
    return arr;
}

/* Sort (key, idx) pairs by key, stably: LSD radix, a byte at a time, skipping the bytes
 * all keys share. */
static int radix_sort(uint64_t *key, int32_t *idx, int64_t n)
{
    uint64_t *k2 = malloc((n ? n : 1) * sizeof(uint64_t));
    int32_t *i2 = malloc((n ? n : 1) * sizeof(int32_t));
    if (!k2 || !i2) {
        free(k2);
        free(i2);
        return 0;
    }
    uint64_t differ = 0;
    for (int64_t i = 1; i < n; i++)
        differ |= key[i] ^ key[0];
    for (int shift = 0; shift < 64; shift += 8) {
        if (!((differ >> shift) & 0xff))
            continue;
        int64_t count[257] = {0};
        for (int64_t i = 0; i < n; i++)
            count[((key[i] >> shift) & 0xff) + 1]++;
        for (int b = 0; b < 256; b++)
            count[b + 1] += count[b];
        for (int64_t i = 0; i < n; i++) {
            int64_t to = count[(key[i] >> shift) & 0xff]++;
            k2[to] = key[i];
            i2[to] = idx[i];
        }
        memcpy(key, k2, n * sizeof(uint64_t));
        memcpy(idx, i2, n * sizeof(int32_t));
    }
    free(k2);
    free(i2);
    return 1;
}

/* A growing list of pairs (i, j, d). */
typedef struct {
    int64_t *i, *j;
    double *d;
    int64_t size, cap;
} Pairs;

static int pairs_reserve(Pairs *e, int64_t more)
{
    if (e->size + more <= e->cap)
        return 1;
    int64_t cap = e->cap ? e->cap : 1 << 12;
    while (cap < e->size + more)
        cap *= 2;
    int64_t *i = realloc(e->i, cap * sizeof(int64_t));
    if (i)
        e->i = i;
    int64_t *j = realloc(e->j, cap * sizeof(int64_t));
    if (j)
        e->j = j;
    double *d = realloc(e->d, cap * sizeof(double));
    if (d)
        e->d = d;
    if (!i || !j || !d)
        return 0;
    e->cap = cap;
    return 1;
}

/* A grid built by grid(), as C arrays. */
typedef struct {
    const int64_t *order;      /* (a,) active number at each position */
    const double *xyz;         /* (a, 3) coordinates, in cell order */
    const uint64_t *ukey;      /* (cells,) cell keys, ascending */
    const int64_t *cell_start; /* (cells + 1,) first position of each cell */
    int64_t a, cells;
} Grid;

/* Points side by side: those of the 27 cells around one cell, or one point's hits. */
typedef struct {
    double *x, *y, *z, *d2;
    int32_t *at; /* position */
    int64_t size, cap;
} Near;

static int near_reserve(Near *l, int64_t need)
{
    if (need <= l->cap)
        return 1;
    int64_t cap = l->cap ? l->cap : 1024;
    while (cap < need)
        cap *= 2;
    double **f[4] = {&l->x, &l->y, &l->z, &l->d2};
    for (int k = 0; k < 4; k++) {
        double *p = realloc(*f[k], cap * sizeof(double));
        if (!p)
            return 0;
        *f[k] = p;
    }
    int32_t *at = realloc(l->at, cap * sizeof(int32_t));
    if (!at)
        return 0;
    l->at = at;
    l->cap = cap;
    return 1;
}

static void near_free(Near *l)
{
    free(l->x);
    free(l->y);
    free(l->z);
    free(l->d2);
    free(l->at);
}

/* For each cell, the positions of the 27 cells around it, as nine ranges (one per column
 * dx, dy: the cells z - 1 .. z + 1 are consecutive keys): range k of cell c is positions
 * ranges[18 c + 2 k] .. ranges[18 c + 2 k + 1] - 1. Cells are visited in key order, so
 * each column's search goes on from where it stopped. */
static void column_ranges(const Grid *g, int32_t *ranges)
{
    int64_t cursor[9] = {0};
    for (int64_t c = 0; c < g->cells; c++) {
        for (int col = 0; col < 9; col++) {
            int64_t dx = col / 3 - 1, dy = col % 3 - 1;
            uint64_t first = g->ukey[c] + (uint64_t)(dx * ((int64_t)1 << (2 * BITS)) + dy * ((int64_t)1 << BITS) - 1);
            int64_t t = cursor[col];
            while (t < g->cells && g->ukey[t] < first)
                t++;
            cursor[col] = t;
            int64_t end = t;
            while (end < g->cells && g->ukey[end] <= first + 2)
                end++;
            ranges[18 * c + 2 * col] = (int32_t)g->cell_start[t];
            ranges[18 * c + 2 * col + 1] = (int32_t)g->cell_start[end];
        }
    }
}

static int64_t near_count(const int32_t *r)
{
    int64_t n = 0;
    for (int k = 0; k < 9; k++)
        n += r[2 * k + 1] - r[2 * k];
    return n;
}

/* The points of the nine ranges r (18,) side by side in near. */
static int gather(const Grid *g, const int32_t *r, Near *near)
{
    if (!near_reserve(near, near_count(r)))
        return 0;
    near->size = 0;
    for (int k = 0; k < 9; k++)
        for (int64_t s = r[2 * k]; s < r[2 * k + 1]; s++) {
            near->x[near->size] = g->xyz[3 * s];
            near->y[near->size] = g->xyz[3 * s + 1];
            near->z[near->size] = g->xyz[3 * s + 2];
            near->at[near->size++] = (int32_t)s;
        }
    return 1;
}

/* The points of near closer than reach to position s (s itself left out): their index
 * in near into hits->at, their squared distances into hits->d2. No branches in the loops
 * over near, and the first one is vectorised. */
static int close_to(const Grid *g, int64_t s, Near *near, double r2, Near *hits)
{
    if (!near_reserve(hits, near->size))
        return 0;
    double px = g->xyz[3 * s], py = g->xyz[3 * s + 1], pz = g->xyz[3 * s + 2];
    const double *restrict x = near->x, *restrict y = near->y, *restrict z = near->z;
    double *restrict d2 = near->d2;
    for (int64_t l = 0; l < near->size; l++) {
        double dx = px - x[l], dy = py - y[l], dz = pz - z[l];
        double e = dx * dx + dy * dy; /* thinning._self_pairs' order of operations */
        d2[l] = e + dz * dz;
    }
    int64_t w = 0;
    for (int64_t l = 0; l < near->size; l++) {
        hits->at[w] = (int32_t)l;
        hits->d2[w] = d2[l];
        w += (d2[l] < r2) & (near->at[l] != s);
    }
    hits->size = w;
    return 1;
}

static int get_grid(PyObject *args, Grid *g, double *reach, double *radius, PyObject **okept, int *threads)
{
    PyObject *o[4];
    if (!PyArg_ParseTuple(args, okept ? "OOOOddOi" : "OOOOd", &o[0], &o[1], &o[2], &o[3], reach, radius, okept,
                          threads))
        return 0;
    int types[4] = {NPY_INT64, NPY_FLOAT64, NPY_UINT64, NPY_INT64};
    for (int k = 0; k < 4; k++)
        if (!PyArray_Check(o[k]) || PyArray_TYPE((PyArrayObject *)o[k]) != types[k] ||
            !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)o[k])) {
            PyErr_Format(PyExc_TypeError, "grid array %d has the wrong dtype or order", k + 1);
            return 0;
        }
    g->order = PyArray_DATA((PyArrayObject *)o[0]);
    g->xyz = PyArray_DATA((PyArrayObject *)o[1]);
    g->ukey = PyArray_DATA((PyArrayObject *)o[2]);
    g->cell_start = PyArray_DATA((PyArrayObject *)o[3]);
    g->a = PyArray_SIZE((PyArrayObject *)o[0]);
    g->cells = PyArray_SIZE((PyArrayObject *)o[2]);
    if (PyArray_SIZE((PyArrayObject *)o[1]) != 3 * g->a || PyArray_SIZE((PyArrayObject *)o[3]) != g->cells + 1 ||
        g->cell_start[g->cells] != g->a || g->a >= INT32_MAX ||
        (okept && (!PyArray_Check(*okept) || PyArray_TYPE((PyArrayObject *)*okept) != NPY_BOOL ||
                   PyArray_SIZE((PyArrayObject *)*okept) != g->a))) {
        PyErr_Format(PyExc_ValueError, "grid arrays do not match");
        return 0;
    }
    return 1;
}

/* The fine cell of point p, as thinning._Frame.keys: floor((p - lo) / size) + 2, clipped. */
static inline void fine_cell(const double *p, const double *lo, double size, int64_t f[3])
{
    for (int k = 0; k < 3; k++) {
        double v = (p[k] - lo[k]) / size;
        int64_t c = (v >= 0 ? (int64_t)v : (int64_t)floor(v)) + 2; /* floor, cheaply when v >= 0 */
        f[k] = c < 0 ? 0 : (c > MAX_CELLS ? MAX_CELLS : c);
    }
}

PyDoc_STRVAR(grid_doc,
"grid(points, lo, size, cap) -> (active, order, xyz, ukey, cell_start)\n\n"
"points (n, 3) float64 into cells of two fine cells a side, the fine cells (side size)\n"
"from corner lo (3,) float64 as thinning._Frame. With cap > 0 only the first cap points\n"
"(input order) of each fine cell are active, else all. active (a,) int64: their input\n"
"indices, ascending, which numbers them 0..a-1. They are held in cell order: position s\n"
"is active point order[s] (int64) at xyz[s] ((a, 3) float64); cell c has the positions\n"
"cell_start[c] .. cell_start[c + 1] - 1 and key ukey[c] (uint64, ascending).");

static PyObject *grid(PyObject *self, PyObject *args)
{
    PyObject *opts, *olo;
    double size;
    int cap;
    if (!PyArg_ParseTuple(args, "OOdi", &opts, &olo, &size, &cap))
        return NULL;
    if (!PyArray_Check(opts) || PyArray_TYPE((PyArrayObject *)opts) != NPY_FLOAT64 ||
        !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)opts) || PyArray_NDIM((PyArrayObject *)opts) != 2 ||
        PyArray_DIM((PyArrayObject *)opts, 1) != 3)
        return PyErr_Format(PyExc_TypeError, "points must be (n, 3) float64, C order");
    if (!PyArray_Check(olo) || PyArray_TYPE((PyArrayObject *)olo) != NPY_FLOAT64 ||
        !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)olo) || PyArray_SIZE((PyArrayObject *)olo) != 3)
        return PyErr_Format(PyExc_TypeError, "lo must be (3,) float64");
    const double *pts = PyArray_DATA((PyArrayObject *)opts);
    const double *lo = PyArray_DATA((PyArrayObject *)olo);
    int64_t n = PyArray_DIM((PyArrayObject *)opts, 0), m = n ? n : 1;
    if (n >= INT32_MAX)
        return PyErr_Format(PyExc_ValueError, "too many points for the compiled grid");

    int ok = 0;
    int64_t a = 0, cells = 0;
    uint64_t *key = malloc(m * sizeof(uint64_t)), *ukey = malloc(m * sizeof(uint64_t));
    int32_t *perm = malloc(m * sizeof(int32_t)); /* n < 2^31 */
    int64_t *number = malloc(m * sizeof(int64_t));
    int64_t *cell_start = malloc((m + 1) * sizeof(int64_t)), *active = malloc(m * sizeof(int64_t));
    int64_t *order = malloc(m * sizeof(int64_t));
    unsigned char *sub = malloc(m);
    double *xyz = malloc(3 * m * sizeof(double));
    if (!key || !ukey || !perm || !number || !cell_start || !active || !order || !sub || !xyz)
        goto done;

    Py_BEGIN_ALLOW_THREADS
    /* A cell is two fine cells a side (side >= reach); ``sub`` says which of its eight.
       Cells are sorted by a compact key, in the order of their packed keys (x, then y,
       then z), so the radix sort has few bytes to go through. */
    /* cells are monotone in the coordinates: the extreme cells are those of the extremes */
    double pmin[3] = {0, 0, 0}, pmax[3] = {0, 0, 0};
    for (int64_t i = 0; i < n; i++)
        for (int k = 0; k < 3; k++) {
            double v = pts[3 * i + k];
            pmin[k] = i == 0 || v < pmin[k] ? v : pmin[k];
            pmax[k] = i == 0 || v > pmax[k] ? v : pmax[k];
        }
    int64_t cmin[3], cmax[3], f[3];
    fine_cell(pmin, lo, size, cmin);
    fine_cell(pmax, lo, size, cmax);
    for (int k = 0; k < 3; k++) {
        cmin[k] = (cmin[k] >> 1) + 1;
        cmax[k] = (cmax[k] >> 1) + 1;
    }
    int64_t ny = n ? cmax[1] - cmin[1] + 1 : 1, nz = n ? cmax[2] - cmin[2] + 1 : 1;
    for (int64_t i = 0; i < n; i++) {
        fine_cell(pts + 3 * i, lo, size, f);
        key[i] = (uint64_t)((((f[0] >> 1) + 1 - cmin[0]) * ny + ((f[1] >> 1) + 1 - cmin[1])) * nz +
                            ((f[2] >> 1) + 1 - cmin[2]));
        sub[i] = (unsigned char)(((f[0] & 1) << 2) | ((f[1] & 1) << 1) | (f[2] & 1));
        perm[i] = (int32_t)i;
    }
    if (!radix_sort(key, perm, n))
        goto unlock;
    /* the cap: rank in input order within each fine cell (the sort is stable); a point
       past the cap is marked in the spare high bit of its ``sub``. Most point sets have
       none: then every point is active under its own number, and ``number`` is unused. */
    int over = 0;
    int64_t seen[8] = {0};
    for (int64_t s = 0; cap > 0 && s < n; s++) {
        if (s > 0 && key[s] != key[s - 1])
            memset(seen, 0, sizeof(seen));
        if (seen[sub[perm[s]]]++ >= cap) {
            sub[perm[s]] |= 0x80;
            over = 1;
        }
    }
    for (int64_t i = 0; i < n; i++) {
        if (!over)
            active[a++] = i;
        else if (sub[i] & 0x80)
            number[i] = -1;
        else {
            active[a] = i;
            number[i] = a++;
        }
    }
    int64_t k = 0;
    uint64_t last = 0;
    for (int64_t s = 0; s < n; s++) {
        int64_t i = perm[s];
        if (over && number[i] < 0)
            continue;
        if (k == 0 || key[s] != last) {
            last = key[s];
            int64_t z = (int64_t)(last % (uint64_t)nz), y = (int64_t)(last / (uint64_t)nz % (uint64_t)ny);
            int64_t x = (int64_t)(last / (uint64_t)nz / (uint64_t)ny);
            ukey[cells] = pack(x + cmin[0], y + cmin[1], z + cmin[2]);
            cell_start[cells++] = k;
        }
        memcpy(xyz + 3 * k, pts + 3 * i, 3 * sizeof(double));
        order[k++] = over ? number[i] : i;
    }
    cell_start[cells] = a;
    ok = 1;
unlock:
    Py_END_ALLOW_THREADS
done:
    free(key);
    free(perm);
    free(number);
    free(sub);
    if (!ok) {
        free(ukey);
        free(cell_start);
        free(active);
        free(order);
        free(xyz);
        return PyErr_NoMemory();
    }
    PyObject *oxyz = owned_array(NPY_FLOAT64, 3 * a, xyz);
    if (!oxyz)
        return NULL;
    npy_intp dims[2] = {a, 3};
    PyArray_Dims shape = {dims, 2};
    PyObject *xyz2 = PyArray_Newshape((PyArrayObject *)oxyz, &shape, NPY_CORDER);
    Py_DECREF(oxyz);
    return Py_BuildValue("NNNNN", owned_array(NPY_INT64, a, active), owned_array(NPY_INT64, a, order), xyz2,
                         owned_array(NPY_UINT64, cells, ukey), owned_array(NPY_INT64, cells + 1, cell_start));
}

PyDoc_STRVAR(pairs_doc,
"pairs(order, xyz, ukey, cell_start, reach) -> (i, j, d)\n\n"
"Every pair of a grid() closer than reach: i < j (int64) active numbers, d (float64)\n"
"their distance, as thinning._self_pairs (in another order).");

static PyObject *pairs(PyObject *self, PyObject *args)
{
    Grid g;
    double reach, unused = 0;
    if (!get_grid(args, &g, &reach, &unused, NULL, NULL))
        return NULL;
    int ok = 0;
    Pairs e = {0};
    Near near = {0}, hits = {0};
    int32_t *ranges = malloc((18 * g.cells + 1) * sizeof(int32_t));
    if (!ranges)
        return PyErr_NoMemory();
    Py_BEGIN_ALLOW_THREADS
    double r2 = reach * reach;
    column_ranges(&g, ranges);
    for (int64_t c = 0; c < g.cells; c++) {
        if (!gather(&g, ranges + 18 * c, &near))
            goto unlock;
        for (int64_t s = g.cell_start[c]; s < g.cell_start[c + 1]; s++) {
            if (!close_to(&g, s, &near, r2, &hits) || !pairs_reserve(&e, hits.size))
                goto unlock;
            for (int64_t t = 0; t < hits.size; t++) {
                int64_t i = g.order[s], j = g.order[near.at[hits.at[t]]];
                e.i[e.size] = i;
                e.j[e.size] = j;
                e.d[e.size] = sqrt(hits.d2[t]);
                e.size += i < j;
            }
        }
    }
    ok = pairs_reserve(&e, 1); /* an array needs a buffer, even an empty one */
unlock:
    Py_END_ALLOW_THREADS
    free(ranges);
    near_free(&near);
    near_free(&hits);
    if (!ok) {
        free(e.i);
        free(e.j);
        free(e.d);
        return PyErr_NoMemory();
    }
    return Py_BuildValue("NNN", owned_array(NPY_INT64, e.size, e.i), owned_array(NPY_INT64, e.size, e.j),
                         owned_array(NPY_FLOAT64, e.size, e.d));
}

/* The greedy's working arrays. The crowding pass, which finds every point's neighbours,
 * leaves them as a bit mask over the point's ``near`` list (the 27 cells around its
 * cell), so the greedy blocks the neighbours of a kept point without searching again. */
typedef struct {
    const Grid *g;
    const int32_t *ranges;   /* (cells, 18) column_ranges */
    const int64_t *mask_at;  /* (cells + 1,) first mask word of each cell */
    uint64_t *mask;
    uint64_t *crowd;         /* (a,) by active number */
    int64_t *where;          /* (a,) position of each active number */
    int32_t *cell_of;        /* (a,) cell of each position */
    double r2, radius;
} Greedy;

static int64_t words(int64_t bits)
{
    return (bits + 63) / 64;
}

/* The crowding of point p (3,) against the points of near: the sum of
 * floor((1 - d * scale) * CROWD_SCALE) over those at distance d < radius, d from squared
 * distances below r2 (the grid's reach squared), near index ``self`` (p itself) left out.
 * Those points' bits are set in mask (words(near->size) words), the others cleared. A
 * first pass marks the points within reach word by word with no branches; only they go
 * on to the square root. */
static uint64_t crowding_of(const double *p, int64_t self, Near *near, double r2, double radius, double scale,
                            uint64_t *mask)
{
    const double *restrict x = near->x, *restrict y = near->y, *restrict z = near->z;
    double *restrict d2 = near->d2;
    int64_t n = near->size;
    for (int64_t l = 0; l < n; l++) {
        double dx = p[0] - x[l], dy = p[1] - y[l], dz = p[2] - z[l];
        double e = dx * dx + dy * dy; /* thinning._self_pairs' order of operations */
        d2[l] = e + dz * dz;
    }
    uint64_t sum = 0;
    for (int64_t word = 0; 64 * word < n; word++) {
        int64_t end = n - 64 * word < 64 ? n - 64 * word : 64;
        const double *dw = d2 + 64 * word;
        uint64_t bits = 0;
        for (int64_t b = 0; b < end; b++)
            bits |= (uint64_t)(dw[b] < r2) << b;
        if (self >= 64 * word && self < 64 * word + 64)
            bits &= ~((uint64_t)1 << (self - 64 * word));
        for (uint64_t left = bits; left; left &= left - 1) {
            int b = __builtin_ctzll(left);
            double d = sqrt(dw[b]);
            if (d < radius) /* makes the weight positive, so truncation is floor */
                sum += (uint64_t)(int64_t)((1.0 - d * scale) * CROWD_SCALE);
            else
                bits &= ~((uint64_t)1 << b);
        }
        mask[word] = bits;
    }
    return sum;
}

typedef struct {
    const Greedy *w;
    int64_t c0, c1;
    int ok;
} CrowdJob;

/* Crowding of the points of cells c0 .. c1 - 1, and their neighbour masks. */
static void *crowd_job(void *arg)
{
    CrowdJob *job = arg;
    const Greedy *w = job->w;
    const Grid *g = w->g;
    Near near = {0};
    double scale = 1.0 / (2.0 * w->radius);
    job->ok = 1;
    for (int64_t c = job->c0; job->ok && c < job->c1; c++) {
        const int32_t *r = w->ranges + 18 * c;
        job->ok = gather(g, r, &near);
        int64_t nw = words(near.size), self = 0; /* near index of the cell's first point */
        for (int k = 0; k < 4; k++)
            self += r[2 * k + 1] - r[2 * k];
        self += g->cell_start[c] - r[8];
        for (int64_t s = g->cell_start[c]; job->ok && s < g->cell_start[c + 1]; s++, self++) {
            uint64_t *mask = w->mask + w->mask_at[c] + (s - g->cell_start[c]) * nw;
            w->crowd[g->order[s]] = crowding_of(g->xyz + 3 * s, self, &near, w->r2, w->radius, scale, mask);
            w->where[g->order[s]] = s;
            w->cell_of[s] = (int32_t)c;
        }
    }
    near_free(&near);
    return NULL;
}

#define MAX_THREADS 16

/* The crowding pass over all cells, split between threads (each point's sum and mask are
 * its own, so the split changes nothing). */
static int crowding(const Greedy *w, int threads)
{
    CrowdJob jobs[MAX_THREADS];
    pthread_t ids[MAX_THREADS];
    int started[MAX_THREADS] = {0}, ok = 1;
    int64_t cells = w->g->cells;
    threads = threads < 1 ? 1 : (threads > MAX_THREADS ? MAX_THREADS : threads);
    if (cells < 1024 * threads)
        threads = 1;
    for (int k = 0; k < threads; k++) {
        CrowdJob job = {w, cells * k / threads, cells * (k + 1) / threads, 0};
        jobs[k] = job;
        if (k > 0)
            started[k] = pthread_create(&ids[k], NULL, crowd_job, &jobs[k]) == 0;
    }
    crowd_job(&jobs[0]);
    for (int k = 1; k < threads; k++) {
        if (started[k])
            pthread_join(ids[k], NULL);
        else
            crowd_job(&jobs[k]);
    }
    for (int k = 0; k < threads; k++)
        ok &= jobs[k].ok;
    return ok;
}

/* Block the neighbours of position s, read from its mask. */
static void block_around(const Greedy *w, int64_t s, char *blocked)
{
    const Grid *g = w->g;
    int64_t c = w->cell_of[s];
    const int32_t *r = w->ranges + 18 * c;
    int64_t nw = words(near_count(r));
    const uint64_t *mask = w->mask + w->mask_at[c] + (s - g->cell_start[c]) * nw;
    int k = 0;
    int64_t before = 0; /* near index of range k's first point */
    for (int64_t word = 0; word < nw; word++) {
        for (uint64_t bits = mask[word]; bits; bits &= bits - 1) {
            int64_t l = 64 * word + __builtin_ctzll(bits);
            while (l >= before + r[2 * k + 1] - r[2 * k]) {
                before += r[2 * k + 1] - r[2 * k];
                k++;
            }
            blocked[r[2 * k] + (l - before)] = 1;
        }
    }
}

PyDoc_STRVAR(greedy_doc,
"greedy(order, xyz, ukey, cell_start, reach, radius, kept, threads)\n\n"
"Maximal independent set of the pairs of a grid() closer than reach whose distance is\n"
"below radius, taken in ascending crowding (sum of floor((1 - d * (1 / (2 radius))) * 65536)\n"
"over those pairs), ties by active number: thinning._least_crowded_first on the pairs\n"
"of thinning._self_pairs(..., reach). Fills kept (a,) bool, by active number. The\n"
"crowding is summed on ``threads`` threads; the result does not depend on how many.");

static PyObject *greedy(PyObject *self, PyObject *args)
{
    Grid g;
    double reach, radius;
    PyObject *okept;
    int threads;
    if (!get_grid(args, &g, &reach, &radius, &okept, &threads))
        return NULL;
    npy_bool *kept = PyArray_DATA((PyArrayObject *)okept);
    int64_t a = g.a, m = a ? a : 1;
    Greedy w = {&g, NULL, NULL, NULL, NULL, NULL, NULL, reach * reach, radius};
    int32_t *ranges = malloc((18 * g.cells + 1) * sizeof(int32_t));
    int64_t *mask_at = malloc((g.cells + 1) * sizeof(int64_t));
    uint64_t *mask = NULL, *crowd = malloc(m * sizeof(uint64_t));
    int32_t *rank = malloc(m * sizeof(int32_t)); /* a < 2^31 */
    int64_t *where = malloc(m * sizeof(int64_t));
    int32_t *cell_of = malloc(m * sizeof(int32_t));
    char *blocked = calloc(m, 1);
    int ok = ranges && mask_at && crowd && rank && where && cell_of && blocked;
    Py_BEGIN_ALLOW_THREADS
    if (ok) {
        column_ranges(&g, ranges);
        mask_at[0] = 0;
        for (int64_t c = 0; c < g.cells; c++)
            mask_at[c + 1] = mask_at[c] + (g.cell_start[c + 1] - g.cell_start[c]) * words(near_count(ranges + 18 * c));
        mask = malloc((mask_at[g.cells] + 1) * sizeof(uint64_t));
        ok = mask != NULL;
    }
    if (ok) {
        Greedy filled = {&g, ranges, mask_at, mask, crowd, where, cell_of, reach * reach, radius};
        w = filled;
        ok = crowding(&w, threads);
    }
    if (ok) {
        for (int64_t p = 0; p < a; p++)
            rank[p] = (int32_t)p;
        ok = radix_sort(crowd, rank, a); /* stable: ties stay in active-number order */
    }
    if (ok) {
        memset(kept, 0, (size_t)a);
        for (int64_t k = 0; k < a; k++) {
            if (k + 16 < a) /* the walk jumps about at random: ask for the rows early */
                __builtin_prefetch(where + rank[k + 16]);
            if (k + 8 < a) {
                int64_t ahead = where[rank[k + 8]];
                __builtin_prefetch(blocked + ahead);
                __builtin_prefetch(w.cell_of + ahead);
            }
            int64_t s = where[rank[k]];
            if (blocked[s])
                continue;
            kept[rank[k]] = 1;
            block_around(&w, s, blocked);
        }
    }
    Py_END_ALLOW_THREADS
    free(ranges);
    free(mask_at);
    free(mask);
    free(crowd);
    free(rank);
    free(where);
    free(cell_of);
    free(blocked);
    if (!ok)
        return PyErr_NoMemory();
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"grid", grid, METH_VARARGS, grid_doc},
    {"pairs", pairs, METH_VARARGS, pairs_doc},
    {"greedy", greedy, METH_VARARGS, greedy_doc},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {
    PyModuleDef_HEAD_INIT, "_cthinning",
    "Compiled grid, pair search and greedy thinning, with the same results as thinning.py's NumPy path.", -1,
    methods,
};

PyMODINIT_FUNC PyInit__cthinning(void)
{
    import_array();
    return PyModule_Create(&module);
}
