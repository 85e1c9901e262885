/* What the compiled kernels share: checking an array argument, and memory for large
 * buffers. Included after Python.h and numpy/arrayobject.h. */
#ifndef SCATTER_CKERNEL_H
#define SCATTER_CKERNEL_H

#include <stdlib.h>
#include <sys/mman.h>

#define HUGE_PAGE ((size_t)1 << 21)

/* A hot walk compiled once for each kind of x86-64 CPU, chosen at load (an ifunc): for
 * AVX-512 (x86-64-v4: 32 vector registers, masks), for AVX2 (four doubles in one
 * register) and plain. Built with -ffp-contract=off, every clone rounds every operation
 * as the others do: the same bytes on any CPU. */
#if defined(__x86_64__) && defined(__GNUC__) && !defined(__clang__) && defined(__GLIBC__)
#if __GNUC__ >= 11 /* (x86-64-v4 is known from GCC 11) */
#define TARGETS __attribute__((target_clones("arch=x86-64-v4", "avx2", "default")))
#else
#define TARGETS __attribute__((target_clones("avx2", "default")))
#endif
#else
#define TARGETS
#endif

/* size bytes, aligned to 64, for a large buffer read in random order: on huge pages
 * where the system offers them (as NumPy asks for its own large arrays), so that fewer
 * reads miss the address cache and fewer pages fault in. Freed with free(). */
static inline void *large_alloc(size_t size)
{
#ifdef MADV_HUGEPAGE
    void *p = NULL;
    if (size >= HUGE_PAGE && posix_memalign(&p, HUGE_PAGE, size) == 0) {
        madvise(p, size, MADV_HUGEPAGE); /* a hint: without huge pages the buffer is as good */
        return p;
    }
#endif
    return aligned_alloc(64, (size + 63) / 64 * 64);
}

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
