/* Embree scenes without embreex's per-element copy loops: the same library (the one the
 * embreex wheel ships), called directly.
 *
 * embreex builds a triangle geometry by copying the vertex and index arrays into Embree
 * one element at a time through Python indexing (docs/exterior.md, "Speed"); here the
 * geometry shares the caller's arrays (no copy at all), and occlusion queries run with
 * the GIL released, so that the caller's threads cast at once. The scene is built as
 * embreex builds it (robust flag, default build quality, one triangle geometry per
 * mesh) and the rays are the ones embreex casts (tnear 0, tfar 1e37, every mask bit),
 * so both give the same verdicts (tests/test_rayscene.py).
 *
 * The library is opened at run time (dlopen) from the path the caller finds: there is
 * nothing of Embree's to compile or link against at install, and without embreex this
 * module is never used.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include "_ckernel.h"
#include <dlfcn.h>
#include <stdint.h>

/* The parts of Embree 4's API used here (embree4/rtcore_*.h). */
typedef void *RTCDevice;
typedef void *RTCScene;
typedef void *RTCGeometry;

struct __attribute__((aligned(16))) RTCRay {
    float org_x, org_y, org_z, tnear;
    float dir_x, dir_y, dir_z, time;
    float tfar;
    unsigned int mask, id, flags;
};

enum { RTC_GEOMETRY_TYPE_TRIANGLE = 0, RTC_BUFFER_TYPE_INDEX = 0, RTC_BUFFER_TYPE_VERTEX = 1,
       RTC_FORMAT_UINT3 = 0x5003, RTC_FORMAT_FLOAT3 = 0x9003, RTC_SCENE_FLAG_ROBUST = 1 << 2,
       RTC_ERROR_OUT_OF_MEMORY = 4 };

static struct {
    RTCDevice (*newDevice)(const char *);
    int (*getDeviceError)(RTCDevice);
    RTCScene (*newScene)(RTCDevice);
    void (*setSceneFlags)(RTCScene, int);
    void (*commitScene)(RTCScene);
    void (*releaseScene)(RTCScene);
    RTCGeometry (*newGeometry)(RTCDevice, int);
    void (*setSharedGeometryBuffer)(RTCGeometry, int, unsigned int, int, const void *, size_t, size_t, size_t);
    void (*commitGeometry)(RTCGeometry);
    unsigned int (*attachGeometry)(RTCScene, RTCGeometry);
    void (*releaseGeometry)(RTCGeometry);
    void (*occluded1)(RTCScene, struct RTCRay *, void *);
} rtc;
static RTCDevice device;

#define SYMBOL(field, name)                                                              \
    if (!(*(void **)&rtc.field = dlsym(lib, name))) {                                    \
        PyErr_Format(PyExc_OSError, "%s: no symbol %s", path, name);                     \
        return NULL;                                                                     \
    }

/* load(path): open the Embree 4 library at ``path`` and make its device (once). */
static PyObject *load(PyObject *self, PyObject *args)
{
    const char *path;
    if (!PyArg_ParseTuple(args, "s", &path))
        return NULL;
    if (device)
        Py_RETURN_NONE;
    void *lib = dlopen(path, RTLD_NOW | RTLD_LOCAL);
    if (!lib) {
        PyErr_Format(PyExc_OSError, "%s", dlerror());
        return NULL;
    }
    SYMBOL(newDevice, "rtcNewDevice")
    SYMBOL(getDeviceError, "rtcGetDeviceError")
    SYMBOL(newScene, "rtcNewScene")
    SYMBOL(setSceneFlags, "rtcSetSceneFlags")
    SYMBOL(commitScene, "rtcCommitScene")
    SYMBOL(releaseScene, "rtcReleaseScene")
    SYMBOL(newGeometry, "rtcNewGeometry")
    SYMBOL(setSharedGeometryBuffer, "rtcSetSharedGeometryBuffer")
    SYMBOL(commitGeometry, "rtcCommitGeometry")
    SYMBOL(attachGeometry, "rtcAttachGeometry")
    SYMBOL(releaseGeometry, "rtcReleaseGeometry")
    SYMBOL(occluded1, "rtcOccluded1")
    device = rtc.newDevice(NULL);
    if (!device) {
        PyErr_SetString(PyExc_OSError, "Embree could not make a device (unsupported CPU?)");
        return NULL;
    }
    Py_RETURN_NONE;
}

static int check_device(void)
{
    int code = rtc.getDeviceError(device);
    if (code) {
        PyErr_Format(code == RTC_ERROR_OUT_OF_MEMORY ? PyExc_MemoryError : PyExc_RuntimeError, "Embree error %d", code);
        return 0;
    }
    return 1;
}

static void release(PyObject *capsule)
{
    RTCScene scene = PyCapsule_GetPointer(capsule, "scatter.embree.scene");
    if (scene)
        rtc.releaseScene(scene);
}

static RTCScene scene_of(PyObject *obj)
{
    return PyCapsule_GetPointer(obj, "scatter.embree.scene");
}

/* new_scene() -> capsule: an empty robust scene. */
static PyObject *new_scene(PyObject *self, PyObject *args)
{
    if (!device) {
        PyErr_SetString(PyExc_RuntimeError, "load() the library first");
        return NULL;
    }
    RTCScene scene = rtc.newScene(device);
    if (!scene || !check_device())
        return NULL;
    rtc.setSceneFlags(scene, RTC_SCENE_FLAG_ROBUST);
    PyObject *capsule = PyCapsule_New(scene, "scatter.embree.scene", release);
    if (!capsule)
        rtc.releaseScene(scene);
    return capsule;
}

/* buffers(vertices (n, 3) float64, center (3,) float64, faces (m, 3) int64) -> (v (n, 4)
 * float32, f (m, 3) int32): the arrays add() shares with Embree, made in one pass each
 * with the GIL released: v - center rounded to float32 (as NumPy's astype rounds it;
 * the fourth column 0: Embree reads 16 bytes a vertex), the indices checked. */
static PyObject *buffers(PyObject *self, PyObject *args)
{
    PyObject *vo, *co, *fo;
    PyArrayObject *v, *c, *f;
    npy_intp n, m;
    if (!PyArg_ParseTuple(args, "OOO", &vo, &co, &fo) || !get_rows(vo, NPY_FLOAT64, 3, &v, &n, "vertices") ||
        !get(co, NPY_FLOAT64, 3, &c, "center") || !get_rows(fo, NPY_INT64, 3, &f, &m, "faces"))
        return NULL;
    if (n > INT32_MAX) {
        PyErr_SetString(PyExc_ValueError, "more than 2**31 - 1 vertices");
        return NULL;
    }
    npy_intp vshape[2] = {n, 4}, fshape[2] = {m, 3};
    PyArrayObject *v4 = (PyArrayObject *)PyArray_SimpleNew(2, vshape, NPY_FLOAT32);
    PyArrayObject *f32 = (PyArrayObject *)PyArray_SimpleNew(2, fshape, NPY_INT32);
    if (!v4 || !f32) {
        Py_XDECREF(v4), Py_XDECREF(f32);
        return NULL;
    }
    const double *src = PyArray_DATA(v), *center = PyArray_DATA(c);
    const int64_t *idx = PyArray_DATA(f);
    float *dst = PyArray_DATA(v4);
    int32_t *out = PyArray_DATA(f32);
    uint64_t bad = 0;
    Py_BEGIN_ALLOW_THREADS
    for (npy_intp i = 0; i < n; i++) {
        for (int k = 0; k < 3; k++)
            dst[4 * i + k] = (float)(src[3 * i + k] - center[k]);
        dst[4 * i + 3] = 0.0f;
    }
    for (npy_intp i = 0; i < 3 * m; i++) {
        bad |= (uint64_t)idx[i] >= (uint64_t)n;
        out[i] = (int32_t)idx[i];
    }
    Py_END_ALLOW_THREADS
    if (bad) {
        Py_DECREF(v4), Py_DECREF(f32);
        PyErr_SetString(PyExc_ValueError, "faces: a vertex index out of range");
        return NULL;
    }
    return Py_BuildValue("NN", v4, f32);
}

/* add(scene, vertices (n, 4) float32, faces (m, 3) int32): one triangle geometry sharing
 * both arrays, which the caller keeps alive as long as the scene. Indices are checked. */
static PyObject *add(PyObject *self, PyObject *args)
{
    PyObject *cap, *vo, *fo;
    PyArrayObject *v, *f;
    if (!PyArg_ParseTuple(args, "OOO", &cap, &vo, &fo))
        return NULL;
    RTCScene scene = scene_of(cap);
    npy_intp n, m;
    if (!scene || !get_rows(vo, NPY_FLOAT32, 4, &v, &n, "vertices") || !get_rows(fo, NPY_INT32, 3, &f, &m, "faces"))
        return NULL;
    const int32_t *idx = PyArray_DATA(f);
    for (npy_intp i = 0; i < 3 * m; i++)
        if (idx[i] < 0 || idx[i] >= n) {
            PyErr_SetString(PyExc_ValueError, "faces: a vertex index out of range");
            return NULL;
        }
    if (!m)
        Py_RETURN_NONE;
    RTCGeometry geom = rtc.newGeometry(device, RTC_GEOMETRY_TYPE_TRIANGLE);
    if (!geom || !check_device())
        return NULL;
    rtc.setSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_VERTEX, 0, RTC_FORMAT_FLOAT3, PyArray_DATA(v), 0,
                                4 * sizeof(float), (size_t)n);
    rtc.setSharedGeometryBuffer(geom, RTC_BUFFER_TYPE_INDEX, 0, RTC_FORMAT_UINT3, idx, 0,
                                3 * sizeof(int32_t), (size_t)m);
    rtc.commitGeometry(geom);
    rtc.attachGeometry(scene, geom);
    rtc.releaseGeometry(geom);
    if (!check_device())
        return NULL;
    Py_RETURN_NONE;
}

/* commit(scene): build the tree (Embree's own threads; the GIL released). */
static PyObject *commit(PyObject *self, PyObject *args)
{
    PyObject *cap;
    if (!PyArg_ParseTuple(args, "O", &cap))
        return NULL;
    RTCScene scene = scene_of(cap);
    if (!scene)
        return NULL;
    Py_BEGIN_ALLOW_THREADS
    rtc.commitScene(scene);
    Py_END_ALLOW_THREADS
    if (!check_device())
        return NULL;
    Py_RETURN_NONE;
}

/* occluded(scene, origins (m, 3) float32, directions (m, 3) float32, out (m,) bool):
 * out[i] = the ray i hits a face (committed scene; the GIL released). */
static PyObject *occluded(PyObject *self, PyObject *args)
{
    PyObject *cap, *oo, *dobj, *out_o;
    PyArrayObject *o, *d, *out;
    if (!PyArg_ParseTuple(args, "OOOO", &cap, &oo, &dobj, &out_o))
        return NULL;
    RTCScene scene = scene_of(cap);
    if (!scene || !get(out_o, NPY_BOOL, -1, &out, "out"))
        return NULL;
    npy_intp m = PyArray_SIZE(out);
    if (!get(oo, NPY_FLOAT32, 3 * m, &o, "origins") || !get(dobj, NPY_FLOAT32, 3 * m, &d, "directions"))
        return NULL;
    const float *org = PyArray_DATA(o), *dir = PyArray_DATA(d);
    npy_bool *hit = PyArray_DATA(out);
    Py_BEGIN_ALLOW_THREADS
    struct RTCRay ray;
    for (npy_intp i = 0; i < m; i++) {
        ray.org_x = org[3 * i], ray.org_y = org[3 * i + 1], ray.org_z = org[3 * i + 2];
        ray.dir_x = dir[3 * i], ray.dir_y = dir[3 * i + 1], ray.dir_z = dir[3 * i + 2];
        ray.tnear = 0.0f, ray.time = 0.0f, ray.tfar = 1e37f;
        ray.mask = 0xFFFFFFFFu, ray.id = 0, ray.flags = 0;
        rtc.occluded1(scene, &ray, NULL);
        hit[i] = ray.tfar < 0.0f;  /* Embree sets tfar to -inf on a hit */
    }
    Py_END_ALLOW_THREADS
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"load", load, METH_VARARGS, "load(path): open the Embree 4 library at path (once)."},
    {"new_scene", new_scene, METH_NOARGS, "new_scene() -> an empty robust scene."},
    {"buffers", buffers, METH_VARARGS,
     "buffers(vertices (n, 3) float64, center (3,) float64, faces (m, 3) int64) -> (vertices (n, 4) float32, "
     "faces (m, 3) int32): the arrays add() shares, vertices less center."},
    {"add", add, METH_VARARGS, "add(scene, vertices (n, 4) float32, faces (m, 3) int32): a shared triangle geometry."},
    {"commit", commit, METH_VARARGS, "commit(scene): build the tree."},
    {"occluded", occluded, METH_VARARGS, "occluded(scene, origins, directions, out): whether each ray hits."},
    {NULL, NULL, 0, NULL}};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_cembree", NULL, -1, methods};

PyMODINIT_FUNC PyInit__cembree(void)
{
    import_array();
    return PyModule_Create(&module);
}
