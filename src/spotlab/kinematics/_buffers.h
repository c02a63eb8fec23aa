/* Buffers of spotlab's kinematics kernels: the Python glue their C files share.
 *
 * Each kernel takes numpy arrays through the buffer protocol (no numpy headers): a
 * C-contiguous float64 buffer of an exact length, writable where the kernel writes.
 * Included by the _c_*.c files of this folder (setup.py rebuilds them when it changes).
 */
#ifndef SPOTLAB_KINEMATICS_BUFFERS_H
#define SPOTLAB_KINEMATICS_BUFFERS_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <string.h>

/* A contiguous float64 buffer of exactly `count` items; writable if asked. */
static inline int get_buffer(PyObject *obj, Py_buffer *view, Py_ssize_t count, int writable,
                             const char *name)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, view, flags) != 0) {
        return -1;
    }
    if (view->itemsize != (Py_ssize_t)sizeof(double) || view->format == NULL ||
        strcmp(view->format, "d") != 0 || view->len != count * (Py_ssize_t)sizeof(double)) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd contiguous float64 values", name,
                     count);
        PyBuffer_Release(view);
        return -1;
    }
    return 0;
}

/* `count` buffers, those from `first_writable` on writable; none held on failure. */
static inline int get_buffers(PyObject **objs, Py_buffer *views, const Py_ssize_t *counts,
                              const char *const *names, int count, int first_writable)
{
    for (int i = 0; i < count; i++) {
        if (get_buffer(objs[i], &views[i], counts[i], i >= first_writable, names[i]) != 0) {
            for (int j = 0; j < i; j++) {
                PyBuffer_Release(&views[j]);
            }
            return -1;
        }
    }
    return 0;
}

static inline void release(Py_buffer *views, int count)
{
    for (int i = 0; i < count; i++) {
        PyBuffer_Release(&views[i]);
    }
}

#endif
