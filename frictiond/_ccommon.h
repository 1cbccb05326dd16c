/*
 * Helpers shared by frictiond's compiled modules (_fitcore.c, _frontcore.c): arrays through the
 * buffer protocol, short sequences of floats in and tuples of floats out.
 */
#ifndef FRICTIOND_CCOMMON_H
#define FRICTIOND_CCOMMON_H

#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <limits.h>
#include <string.h>

#define MAX_POINTS 16   /* the most values `floats` takes (wheels, peaks: a handful) */

typedef struct {
    Py_buffer view;
    int held;
} Buf;

static inline int get_array(PyObject *obj, Buf *b, const char *name, Py_ssize_t count, int writable, int index)
{
    int flags = PyBUF_C_CONTIGUOUS | PyBUF_FORMAT | (writable ? PyBUF_WRITABLE : 0);
    if (PyObject_GetBuffer(obj, &b->view, flags) < 0)
        return -1;
    b->held = 1;
    const char *f = b->view.format ? b->view.format : "B";
    if (*f == '<' || *f == '=' || *f == '@')
        f++;
    const int ok = index ? (b->view.itemsize == (Py_ssize_t)sizeof(Py_ssize_t) && (*f == 'l' || *f == 'q' || *f == 'n'))
                         : (b->view.itemsize == 8 && *f == 'd');
    if (!ok) {
        PyErr_Format(PyExc_TypeError, "%s: expected a contiguous %s array", name, index ? "intp" : "float64");
        return -1;
    }
    if (count >= 0 && b->view.len / b->view.itemsize != count) {
        PyErr_Format(PyExc_ValueError, "%s: expected %zd values, got %zd", name, count, b->view.len / b->view.itemsize);
        return -1;
    }
    return 0;
}

/* METH_FASTCALL argument conversion: what PyArg_ParseTuple's "d", "n" and "i" do, without
 * interpreting a format string on every call (most of a hot call's overhead). 0 with an exception. */
static inline int arg_double(PyObject *o, double *out)
{
    *out = PyFloat_CheckExact(o) ? PyFloat_AS_DOUBLE(o) : PyFloat_AsDouble(o);
    return !(*out == -1.0 && PyErr_Occurred());
}

static inline int arg_ssize(PyObject *o, Py_ssize_t *out)
{
    *out = PyNumber_AsSsize_t(o, PyExc_OverflowError);
    return !(*out == -1 && PyErr_Occurred());
}

static inline int arg_int(PyObject *o, int *out)
{
    const long v = PyLong_AsLong(o);
    if (v == -1 && PyErr_Occurred())
        return 0;
    if (v > INT_MAX || v < INT_MIN) {
        PyErr_SetString(PyExc_OverflowError, "signed integer is out of range for an int");
        return 0;
    }
    *out = (int)v;
    return 1;
}

static inline int arg_bool(PyObject *o, int *out)   /* "p" */
{
    const int v = PyObject_IsTrue(o);
    if (v < 0)
        return 0;
    *out = v;
    return 1;
}

static inline int arg_type(PyObject *o, PyTypeObject *type, const char *name)   /* "O!" */
{
    if (PyObject_TypeCheck(o, type))
        return 1;
    PyErr_Format(PyExc_TypeError, "%s must be %s, not %.50s", name, type->tp_name, Py_TYPE(o)->tp_name);
    return 0;
}

/* "(dd...d)": exactly n numbers from a sequence. */
static inline int arg_doubles(PyObject *o, double *out, Py_ssize_t n, const char *name)
{
    PyObject *seq = PySequence_Fast(o, name);
    if (!seq)
        return 0;
    int ok = PySequence_Fast_GET_SIZE(seq) == n;
    if (!ok)
        PyErr_Format(PyExc_TypeError, "%s must be a sequence of %zd numbers", name, n);
    for (Py_ssize_t i = 0; ok && i < n; i++)
        ok = arg_double(PySequence_Fast_GET_ITEM(seq, i), &out[i]);
    Py_DECREF(seq);
    return ok;
}

static inline int arg_count(const char *name, Py_ssize_t nargs, Py_ssize_t expected)
{
    if (nargs == expected)
        return 1;
    PyErr_Format(PyExc_TypeError, "%s() takes %zd arguments (%zd given)", name, expected, nargs);
    return 0;
}

static inline void release_all(Buf *b, int n)
{
    for (int i = 0; i < n; i++)
        if (b[i].held)
            PyBuffer_Release(&b[i].view);
}

/* Up to MAX_POINTS floats from a sequence; returns the count or -1 with an exception. */
static inline Py_ssize_t floats(PyObject *obj, double *out, const char *name)
{
    PyObject *seq = PySequence_Fast(obj, name);
    if (!seq)
        return -1;
    const Py_ssize_t n = PySequence_Fast_GET_SIZE(seq);
    if (n > MAX_POINTS) {
        Py_DECREF(seq);
        PyErr_Format(PyExc_ValueError, "%s: at most %d values", name, MAX_POINTS);
        return -1;
    }
    for (Py_ssize_t i = 0; i < n; i++) {
        out[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, i));
        if (out[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(seq);
            return -1;
        }
    }
    Py_DECREF(seq);
    return n;
}

static inline PyObject *tuple_of(const double *v, Py_ssize_t n)
{
    PyObject *t = PyTuple_New(n);
    if (!t)
        return NULL;
    for (Py_ssize_t i = 0; i < n; i++) {
        PyObject *f = PyFloat_FromDouble(v[i]);
        if (!f) {
            Py_DECREF(t);
            return NULL;
        }
        PyTuple_SET_ITEM(t, i, f);
    }
    return t;
}

/* (tuple_of(a), tuple_of(b)); NULL with an exception. */
static inline PyObject *pair_of(const double *a, Py_ssize_t na, const double *b, Py_ssize_t nb)
{
    PyObject *ta = tuple_of(a, na), *tb = ta ? tuple_of(b, nb) : NULL;
    if (!tb) {
        Py_XDECREF(ta);
        return NULL;
    }
    return Py_BuildValue("(NN)", ta, tb);
}

/* A sequence of floats into a new buffer (PyMem); *n gets the length. NULL with an exception. */
static inline double *floats_of(PyObject *obj, Py_ssize_t *n, const char *name)
{
    PyObject *seq = PySequence_Fast(obj, name);
    if (!seq)
        return NULL;
    *n = PySequence_Fast_GET_SIZE(seq);
    double *out = PyMem_Malloc((size_t)(*n + 1) * sizeof(double));
    if (!out) {
        Py_DECREF(seq);
        PyErr_NoMemory();
        return NULL;
    }
    for (Py_ssize_t i = 0; i < *n; i++) {
        out[i] = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(seq, i));
        if (out[i] == -1.0 && PyErr_Occurred()) {
            Py_DECREF(seq);
            PyMem_Free(out);
            return NULL;
        }
    }
    Py_DECREF(seq);
    return out;
}

static inline double sum_of(const double *a, Py_ssize_t n)
{
    double s = 0.0;
    for (Py_ssize_t k = 0; k < n; k++)
        s += a[k];
    return s;
}

/* Python's max(a, b) and min(a, b) for floats: a unless b compares beyond it (so a NaN stays
 * where it is, as in the Python code the compiled modules mirror). */
static inline double py_max(double a, double b) { return b > a ? b : a; }
static inline double py_min(double a, double b) { return b < a ? b : a; }

/* Σ a_k·b_k, in order. */
static inline double dot_of(const double *a, const double *b, Py_ssize_t n)
{
    double s = 0.0;
    for (Py_ssize_t k = 0; k < n; k++)
        s += a[k] * b[k];
    return s;
}

#endif
