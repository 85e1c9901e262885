/* What the compiled kernels share: checking an array argument. Included after
 * Python.h and numpy/arrayobject.h. */
#ifndef SCATTER_CKERNEL_H
#define SCATTER_CKERNEL_H

/* An array argument checked for dtype, C order and size (size < 0: any size). */
static inline int get(PyObject *obj, int type, npy_intp size, PyArrayObject **out, const char *name)
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

/* A (rows, cols) array argument checked for dtype, C order and shape; its rows in *rows. */
static inline int get_rows(PyObject *obj, int type, npy_intp cols, PyArrayObject **out, npy_intp *rows,
                           const char *name)
{
    if (!PyArray_Check(obj) || PyArray_TYPE((PyArrayObject *)obj) != type ||
        !PyArray_IS_C_CONTIGUOUS((PyArrayObject *)obj) || PyArray_NDIM((PyArrayObject *)obj) != 2 ||
        PyArray_DIM((PyArrayObject *)obj, 1) != cols) {
        PyErr_Format(PyExc_TypeError, "%s: must be (n, %d) of the right dtype, C order", name, (int)cols);
        return 0;
    }
    *out = (PyArrayObject *)obj;
    *rows = PyArray_DIM((PyArrayObject *)obj, 0);
    return 1;
}

#endif
