/* What the compiled kernels share: checking an array argument. Included after
 * Python.h and numpy/arrayobject.h. */
#ifndef SCATTER_CKERNEL_H
#define SCATTER_CKERNEL_H

/* An array argument checked for dtype, C order and size (size < 0: any size). */
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

#endif
