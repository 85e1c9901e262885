/* Compiled stable placement: the same numbers as stable.py's NumPy path.
 *
 * Face keys and areas, the arrivals of a range of faces before a time, and the points
 * of arrivals: point by point, the integer and float64 operations that the NumPy code
 * does on whole arrays, in the same order (built with -ffp-contract=off), so the two
 * paths give byte-identical output. The GIL is released while they run.
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
    for (npy_intp i = start; i < stop; i++) {
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
        int r = 0;
        if (less(c[1], c[r]))
            r = 1;
        if (less(c[2], c[r]))
            r = 2;
        double t[9];
        for (int k = 0; k < 3; k++)
            for (int a = 0; a < 3; a++)
                t[3 * k + a] = c[(r + k) % 3][a];
        uint64_t h = seed;
        for (int w = 0; w < 9; w++) {
            h ^= bits(t[w]);
            h += GOLDEN;
            h = mix(h);
        }
        double e1[3], e2[3], n[3];
        for (int a = 0; a < 3; a++) {
            e1[a] = t[3 + a] - t[a];
            e2[a] = t[6 + a] - t[a];
        }
        for (int a = 0; a < 3; a++)
            n[a] = e1[(a + 1) % 3] * e2[(a + 2) % 3] - e1[(a + 2) % 3] * e2[(a + 1) % 3];
        double s = n[0] * n[0];
        s += n[1] * n[1];
        s += n[2] * n[2];
        rot[i] = (uint8_t)r;
        key[i] = h;
        area[i] = 0.5 * sqrt(s);
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
    int c = 0; /* searchsorted(cdf, u, 'right'): entries <= u */
    while (c < m && cdf[c] <= u)
        c++;
    return c;
}

PyDoc_STRVAR(arrivals_doc, "arrivals(key (F,) u8, rate (F,) f8, tau, block_mean, cdf (K,) f8, first, last, t, face, ctr)"
                           " -> count: stable.arrivals of faces first..last-1 written to t (f8), face (i8), ctr (u8) "
                           "(None: only counted).");

static PyObject *arrivals(PyObject *self, PyObject *args)
{
    PyObject *okey, *orate, *ocdf, *ot, *oface, *octr;
    PyArrayObject *key_a, *rate_a, *cdf_a, *t_a = NULL, *face_a = NULL, *ctr_a = NULL;
    double tau, mean;
    Py_ssize_t first, last;
    if (!PyArg_ParseTuple(args, "OOddOnnOOO", &okey, &orate, &tau, &mean, &ocdf, &first, &last, &ot, &oface, &octr) ||
        !get(okey, NPY_UINT64, -1, &key_a, "key") || !get(orate, NPY_FLOAT64, PyArray_SIZE(key_a), &rate_a, "rate") ||
        !get(ocdf, NPY_FLOAT64, -1, &cdf_a, "cdf"))
        return NULL;
    int fill = ot != Py_None;
    if (fill && (!get(ot, NPY_FLOAT64, -1, &t_a, "t") || !get(oface, NPY_INT64, PyArray_SIZE(t_a), &face_a, "face") ||
                 !get(octr, NPY_UINT64, PyArray_SIZE(t_a), &ctr_a, "ctr")))
        return NULL;
    if (first < 0 || last > PyArray_SIZE(key_a) || first > last || PyArray_SIZE(cdf_a) >= (1 << COUNT_BITS)) {
        PyErr_SetString(PyExc_ValueError, "arrivals: bad range or table");
        return NULL;
    }
    const uint64_t *key = PyArray_DATA(key_a);
    const double *rate = PyArray_DATA(rate_a), *cdf = PyArray_DATA(cdf_a);
    int m = (int)PyArray_SIZE(cdf_a);
    npy_intp cap = fill ? PyArray_SIZE(t_a) : 0, n = 0;
    double *t = fill ? PyArray_DATA(t_a) : NULL;
    int64_t *face = fill ? PyArray_DATA(face_a) : NULL;
    uint64_t *ctr = fill ? PyArray_DATA(ctr_a) : NULL;
    int over = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = first; i < last && !over; i++) {
        double length = mean / rate[i];
        int64_t nb = blocks_before(tau, length);
        for (int64_t b = 0; b < nb; b++) {
            uint64_t state = lane(key[i], (uint64_t)(b + 1));
            int c = poisson(to_unit(lane(state, 0)), cdf, m);
            if (!fill && (double)(b + 1) * length < tau) {
                n += c; /* every time (b + u) length is at most (b + 1) length, rounded too */
                continue;
            }
            for (int j = 0; j < c; j++) {
                double time = ((double)b + to_unit(lane(state, (uint64_t)(1 + LANES * j)))) * length;
                if (time < tau) {
                    if (fill) {
                        if (n >= cap) {
                            over = 1;
                            break;
                        }
                        t[n] = time;
                        face[n] = i;
                        ctr[n] = ((uint64_t)b << COUNT_BITS) | (uint64_t)j;
                    }
                    n++;
                }
            }
        }
    }
    Py_END_ALLOW_THREADS
    if (over || (fill && n != cap)) {
        PyErr_SetString(PyExc_ValueError, "arrivals: output size differs from the count");
        return NULL;
    }
    return PyLong_FromSsize_t(n);
}

PyDoc_STRVAR(place_doc, "place(used (n,) i8, ctr (n,) u8, key (U,) u8, rot (U,) u1, face (U,) i8, faces (F,3) i8, "
                        "vertices (V,3) f8, points (n,3) f8, b (n,2) f8, order (n,) i8): points of arrivals on one "
                        "instance (stable.StableSource._place, square-root warp), taken in the given order.");

static PyObject *place(PyObject *self, PyObject *args)
{
    PyObject *oused, *octr, *okey, *orot, *oface, *ofaces, *overts, *opts, *ob, *oorder;
    PyArrayObject *used_a, *ctr_a, *key_a, *rot_a, *face_a, *faces_a, *verts_a, *pts_a, *b_a, *order_a;
    if (!PyArg_ParseTuple(args, "OOOOOOOOOO", &oused, &octr, &okey, &orot, &oface, &ofaces, &overts, &opts, &ob,
                          &oorder) ||
        !get(oused, NPY_INT64, -1, &used_a, "used") || !get(octr, NPY_UINT64, PyArray_SIZE(used_a), &ctr_a, "ctr") ||
        !get(okey, NPY_UINT64, -1, &key_a, "key") || !get(orot, NPY_UINT8, PyArray_SIZE(key_a), &rot_a, "rot") ||
        !get(oface, NPY_INT64, PyArray_SIZE(key_a), &face_a, "face") || !get(ofaces, NPY_INT64, -1, &faces_a, "faces") ||
        !get(overts, NPY_FLOAT64, -1, &verts_a, "vertices") ||
        !get(opts, NPY_FLOAT64, 3 * PyArray_SIZE(used_a), &pts_a, "points") ||
        !get(ob, NPY_FLOAT64, 2 * PyArray_SIZE(used_a), &b_a, "b") ||
        !get(oorder, NPY_INT64, PyArray_SIZE(used_a), &order_a, "order"))
        return NULL;
    npy_intp n = PyArray_SIZE(used_a), nu = PyArray_SIZE(key_a), nf = PyArray_SIZE(faces_a) / 3,
             nv = PyArray_SIZE(verts_a) / 3;
    const int64_t *used = PyArray_DATA(used_a), *face = PyArray_DATA(face_a), *fa = PyArray_DATA(faces_a);
    const uint64_t *ctr = PyArray_DATA(ctr_a), *key = PyArray_DATA(key_a);
    const uint8_t *rot = PyArray_DATA(rot_a);
    const double *v = PyArray_DATA(verts_a);
    double *pts = PyArray_DATA(pts_a), *bo = PyArray_DATA(b_a);
    const int64_t *order = PyArray_DATA(order_a);
    int bad = 0;
    Py_BEGIN_ALLOW_THREADS
    /* In passes over blocks of points, so that the cache misses of a pass (face tables,
     * then face corners, then vertices) are independent of each other and overlap. */
    for (npy_intp i0 = 0; i0 < n && !bad; i0 += PASS) {
        npy_intp m = n - i0 < PASS ? n - i0 : PASS;
        int64_t vi[PASS][3], fi[PASS], at[PASS];
        uint8_t r[PASS];
        for (npy_intp k = 0; k < m; k++) {
            int64_t o = order[i0 + k];
            if (o < 0 || o >= n) {
                bad = 1;
                o = 0;
            }
            at[k] = o;
            int64_t u = used[o];
            if (u < 0 || u >= nu || face[u] < 0 || face[u] >= nf) {
                bad = 1;
                u = 0;
            }
            uint64_t c = ctr[o];
            uint64_t state = lane(key[u], (c >> COUNT_BITS) + 1);
            uint64_t j = (c & ((1u << COUNT_BITS) - 1)) * LANES;
            double s = sqrt(to_unit(lane(state, j + 2)));
            double b1 = 1.0 - s;
            bo[2 * o] = b1;
            bo[2 * o + 1] = (1.0 - b1) * to_unit(lane(state, j + 3));
            fi[k] = face[u];
            r[k] = rot[u];
        }
        for (npy_intp k = 0; k < m; k++)
            for (int c = 0; c < 3; c++) {
                int64_t x = fa[3 * fi[k] + (r[k] + c) % 3];
                if (x < 0 || x >= nv) {
                    bad = 1;
                    x = 0;
                }
                vi[k][c] = x;
            }
        for (npy_intp k = 0; k < m; k++) {
            const double *c0 = v + 3 * vi[k][0], *c1 = v + 3 * vi[k][1], *c2 = v + 3 * vi[k][2];
            double b1 = bo[2 * at[k]], b2 = bo[2 * at[k] + 1];
            for (int a = 0; a < 3; a++) {
                double col = (c1[a] - c0[a]) * b1;
                col += (c2[a] - c0[a]) * b2;
                col += c0[a];
                pts[3 * at[k] + a] = col;
            }
        }
    }
    Py_END_ALLOW_THREADS
    if (bad) {
        PyErr_SetString(PyExc_ValueError, "place: index out of range");
        return NULL;
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"faces", faces, METH_VARARGS, faces_doc},
    {"arrivals", arrivals, METH_VARARGS, arrivals_doc},
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
