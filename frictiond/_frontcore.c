/*
 * frictiond._frontcore: the front end's per-sample numerics, compiled.
 *
 * `FrontEnd._fit_wheels` (the derivative filter: a local quadratic fit of the four wheel
 * speeds over the window, its glitch test and the torque weights matched to it) and the
 * weighted sums of `FrontEnd._matched` (a signal interpolated at the window's times, weighted
 * as the filter weights the wheel's acceleration; several signals at once), the interpolation of
 * a sample's inputs (`_MessageHistory.value_at`, batched) and `_MessageHistory.push`'s loop
 * (each decoded value onto its signal's history). The Python code stays the reference and
 * the fallback where no compiler was available at install (tests compare the two).
 * Pure numerics: nothing of CAN, nothing of the tyre model.
 */
#include "_ccommon.h"
#include <math.h>

#define NW 4

/* fit_wheels(times, speeds, spike_threshold) -> (t_c, omega, omega_dot, glitch, torque_weights)
 * or None when the timestamps are too degenerate for the closed form (the caller then uses
 * least squares). `speeds`: one 4-sequence per time. */
static PyObject *py_fit_wheels(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_times, *o_speeds;
    double threshold;
    if (!PyArg_ParseTuple(args, "OOd:fit_wheels", &o_times, &o_speeds, &threshold))
        return NULL;
    Py_ssize_t n;
    double *times = floats_of(o_times, &n, "times");
    if (!times)
        return NULL;
    double *buf = PyMem_Malloc((size_t)(4 * (n + 1) + NW * (n + 1)) * sizeof(double));
    PyObject *seq = NULL, *result = NULL;
    if (!buf) {
        PyErr_NoMemory();
        goto out;
    }
    double *u = buf, *u2 = buf + (n + 1), *c = buf + 2 * (n + 1), *interval = buf + 3 * (n + 1);
    double *y = buf + 4 * (n + 1);   /* y[w * (n + 1) + k] */
    seq = PySequence_Fast(o_speeds, "speeds");
    if (!seq)
        goto out;
    if (PySequence_Fast_GET_SIZE(seq) != n || n < 1) {
        PyErr_SetString(PyExc_ValueError, "speeds: one row of four per time (and at least one)");
        goto out;
    }
    for (Py_ssize_t k = 0; k < n; k++) {
        PyObject *row = PySequence_Fast(PySequence_Fast_GET_ITEM(seq, k), "speeds row");
        if (!row)
            goto out;
        if (PySequence_Fast_GET_SIZE(row) != NW) {
            Py_DECREF(row);
            PyErr_SetString(PyExc_ValueError, "speeds: four wheels per row");
            goto out;
        }
        for (int w = 0; w < NW; w++) {
            const double v = PyFloat_AsDouble(PySequence_Fast_GET_ITEM(row, w));
            if (v == -1.0 && PyErr_Occurred()) {
                Py_DECREF(row);
                goto out;
            }
            y[w * (n + 1) + k] = v;
        }
        Py_DECREF(row);
    }
    const double t_c = times[n / 2];
    double h = fmax(fabs(times[0] - t_c), fabs(times[n - 1] - t_c));
    if (h == 0.0)
        h = 1.0;
    for (Py_ssize_t k = 0; k < n; k++) {
        u[k] = (times[k] - t_c) / h;
        u2[k] = u[k] * u[k];
    }
    const double s1 = sum_of(u, n), s2 = sum_of(u2, n), s3 = dot_of(u, u2, n), s4 = dot_of(u2, u2, n);
    const double dn = (double)n;
    /* Symmetric 3x3 normal matrix [[n, s1, s2], [s1, s2, s3], [s2, s3, s4]]: its adjugate. */
    const double c00 = s2 * s4 - s3 * s3, c01 = s2 * s3 - s1 * s4, c02 = s1 * s3 - s2 * s2;
    const double c11 = dn * s4 - s2 * s2, c12 = s1 * s2 - dn * s3, c22 = dn * s2 - s1 * s1;
    const double det = dn * c00 + s1 * c01 + s2 * c02;
    if (!(det > 1e-9 * fmax(dn * s2 * s4, 1e-300))) {
        result = Py_None;
        Py_INCREF(result);
        goto out;
    }
    const double inv = 1.0 / det;
    int glitch = 0.0 > threshold;
    double omega[NW], omega_dot[NW];
    for (int w = 0; w < NW; w++) {
        const double *yw = y + w * (n + 1);
        const double b0 = sum_of(yw, n), b1 = dot_of(u, yw, n), b2 = dot_of(u2, yw, n);
        const double k0 = (c00 * b0 + c01 * b1 + c02 * b2) * inv;
        const double k1 = (c01 * b0 + c11 * b1 + c12 * b2) * inv;
        const double k2 = (c02 * b0 + c12 * b1 + c22 * b2) * inv;
        for (Py_ssize_t k = 0; k < n && !glitch; k++)
            if (fabs(yw[k] - (k0 + k1 * u[k] + k2 * u2[k])) > threshold)
                glitch = 1;
        omega[w] = k0;
        omega_dot[w] = k1 / h;
    }
    /* frontend._matched_weights with coef = (c01, c11, c12)·inv/h. */
    const double q0 = c01 * inv / h, q1 = c11 * inv / h, q2 = c12 * inv / h;
    for (Py_ssize_t k = 0; k < n; k++)
        c[k] = q0 + q1 * u[k] + q2 * u[k] * u[k];
    double tail = 0.0;
    for (Py_ssize_t k = 0; k <= n; k++)
        interval[k] = 0.0;
    for (Py_ssize_t j = n - 1; j > 0; j--) {
        tail += c[j];
        interval[j] = tail * (times[j] - times[j - 1]);
    }
    for (Py_ssize_t k = 0; k < n; k++)
        c[k] = 0.5 * (interval[k] + interval[k + 1]);
    {
        PyObject *a = tuple_of(omega, NW), *b = a ? tuple_of(omega_dot, NW) : NULL, *wt = b ? tuple_of(c, n) : NULL;
        if (wt)
            result = Py_BuildValue("(dNNON)", t_c, a, b, glitch ? Py_True : Py_False, wt);
        else {
            Py_XDECREF(a);
            Py_XDECREF(b);
        }
    }
out:
    Py_XDECREF(seq);
    PyMem_Free(buf);
    PyMem_Free(times);
    return result;
}

/* matched(ts, vs, times, weights, floor) -> Σ_k weights_k·x(times_k), x interpolated linearly
 * in the series (ts, vs) and held beyond its ends, as FrontEnd._matched with
 * frontend._interpolation_plan; with a floor, each series value v counts as max(0, v − floor). */
/* FrontEnd._matched of one series (o_ts, o_vs) over the window's times and weights: *total
 * (each value less floor_value and clipped at 0 when has_floor). 0, or -1 with an exception. */
static int matched_sum(PyObject *o_ts, PyObject *o_vs, const double *times, const double *w, Py_ssize_t nt,
                       int has_floor, double floor_value, double *total_out)
{
    Py_ssize_t ns, nv;
    double *ts = NULL, *vs = NULL, *coef = NULL;
    Py_ssize_t *order = NULL;
    char *seen = NULL;
    int status = -1;
    if (!(ts = floats_of(o_ts, &ns, "ts")) || !(vs = floats_of(o_vs, &nv, "vs")))
        goto out;
    if (ns != nv || ns < 1) {
        PyErr_SetString(PyExc_ValueError, "matched: ts and vs (non-empty) of one length");
        goto out;
    }
    coef = PyMem_Calloc((size_t)ns, sizeof(double));
    order = PyMem_Malloc((size_t)(ns + 1) * sizeof(Py_ssize_t));
    seen = PyMem_Calloc((size_t)ns, 1);
    if (!coef || !order || !seen) {
        PyErr_NoMemory();
        goto out;
    }
    Py_ssize_t n_order = 0;
#define ADD(j_, a_)                           \
    do {                                      \
        if (!seen[j_]) {                      \
            seen[j_] = 1;                     \
            order[n_order++] = (j_);          \
        }                                     \
        coef[j_] += (a_);                     \
    } while (0)
    const Py_ssize_t last = ns - 1;
    Py_ssize_t k = last;
    for (Py_ssize_t i = nt - 1; i >= 0; i--) {   /* newest window time first, as the plan */
        const double t = times[i], wt = w[i];
        if (t >= ts[last]) {
            ADD(last, wt);
            continue;
        }
        while (k > 0 && ts[k - 1] > t)
            k--;
        if (k == 0) {
            ADD(0, wt);
            continue;
        }
        const double t0 = ts[k - 1], t1 = ts[k];
        const double f = t1 > t0 ? (t - t0) / (t1 - t0) : 1.0;
        ADD(k - 1, wt * (1.0 - f));
        ADD(k, wt * f);
    }
#undef ADD
    double total = 0.0;
    for (Py_ssize_t i = 0; i < n_order; i++) {
        const Py_ssize_t j = order[i];
        if (!has_floor)
            total += coef[j] * vs[j];
        else if (vs[j] > floor_value)
            total += coef[j] * (vs[j] - floor_value);
    }
    *total_out = total;
    status = 0;
out:
    PyMem_Free(ts);
    PyMem_Free(vs);
    PyMem_Free(coef);
    PyMem_Free(order);
    PyMem_Free(seen);
    return status;
}

/* The window's times and weights as two equal-length float buffers (PyMem); -1 with an exception. */
static int window_of(PyObject *o_times, PyObject *o_w, double **times, double **w, Py_ssize_t *n)
{
    Py_ssize_t nw;
    *times = *w = NULL;
    if (!(*times = floats_of(o_times, n, "times")) || !(*w = floats_of(o_w, &nw, "weights")))
        return -1;
    if (*n != nw) {
        PyErr_SetString(PyExc_ValueError, "matched: times and weights of one length");
        return -1;
    }
    return 0;
}

static PyObject *py_matched(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_ts, *o_vs, *o_times, *o_w, *o_floor;
    if (!PyArg_ParseTuple(args, "OOOOO:matched", &o_ts, &o_vs, &o_times, &o_w, &o_floor))
        return NULL;
    const int has_floor = o_floor != Py_None;
    double floor_value = 0.0;
    if (has_floor && (floor_value = PyFloat_AsDouble(o_floor)) == -1.0 && PyErr_Occurred())
        return NULL;
    double *times, *w, total = 0.0;
    Py_ssize_t nt;
    PyObject *result = NULL;
    if (window_of(o_times, o_w, &times, &w, &nt) == 0
        && matched_sum(o_ts, o_vs, times, w, nt, has_floor, floor_value, &total) == 0)
        result = PyFloat_FromDouble(total);
    PyMem_Free(times);
    PyMem_Free(w);
    return result;
}

/* matched for several signals: ((series dict, name, floor or None) | None, ...) -> tuple of float | None. */
static PyObject *py_matched_many(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *lookups, *o_times, *o_w;
    if (!PyArg_ParseTuple(args, "O!OO:matched_many", &PyTuple_Type, &lookups, &o_times, &o_w))
        return NULL;
    double *times, *w;
    Py_ssize_t nt;
    PyObject *out = NULL;
    if (window_of(o_times, o_w, &times, &w, &nt) < 0)
        goto done;
    const Py_ssize_t count = PyTuple_GET_SIZE(lookups);
    if (!(out = PyTuple_New(count)))
        goto done;
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *lookup = PyTuple_GET_ITEM(lookups, i), *series, *name, *o_floor, *value = NULL;
        if (lookup == Py_None) {
            PyTuple_SET_ITEM(out, i, Py_NewRef(Py_None));
            continue;
        }
        if (!PyArg_ParseTuple(lookup, "O!OO:matched_many", &PyDict_Type, &series, &name, &o_floor))
            goto fail;
        const int has_floor = o_floor != Py_None;
        double floor_value = 0.0, total = 0.0;
        if (has_floor && (floor_value = PyFloat_AsDouble(o_floor)) == -1.0 && PyErr_Occurred())
            goto fail;
        PyObject *pair = PyDict_GetItemWithError(series, name);
        if (!pair) {
            if (PyErr_Occurred())
                goto fail;
            value = Py_NewRef(Py_None);   /* no series yet: the caller's fallback */
        } else {
            if (!PyTuple_Check(pair) || PyTuple_GET_SIZE(pair) != 2) {
                PyErr_SetString(PyExc_TypeError, "matched_many: a series is a (times, values) pair");
                goto fail;
            }
            if (matched_sum(PyTuple_GET_ITEM(pair, 0), PyTuple_GET_ITEM(pair, 1), times, w, nt, has_floor, floor_value,
                            &total) < 0
                || !(value = PyFloat_FromDouble(total)))
                goto fail;
        }
        PyTuple_SET_ITEM(out, i, value);
    }
    goto done;
fail:
    Py_CLEAR(out);
done:
    PyMem_Free(times);
    PyMem_Free(w);
    return out;
}

/* _MessageHistory.value_at for one signal: its (times, values) deques at time t; a new reference. */
static PyObject *value_at(PyObject *pair, double t)
{
    if (!PyTuple_Check(pair) || PyTuple_GET_SIZE(pair) != 2) {
        PyErr_SetString(PyExc_TypeError, "values_at: a series is a (times, values) pair");
        return NULL;
    }
    PyObject *times = PyTuple_GET_ITEM(pair, 0), *values = PyTuple_GET_ITEM(pair, 1);
    const Py_ssize_t n = PySequence_Size(times);
    if (n < 1 || PySequence_Size(values) != n) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "values_at: an empty or ragged series");
        return NULL;
    }
    double t1 = 0.0, t0;
    for (Py_ssize_t k = n - 1; k >= 0; k--) {
        PyObject *item = PySequence_GetItem(times, k);
        if (!item)
            return NULL;
        t0 = PyFloat_AsDouble(item);
        Py_DECREF(item);
        if (t0 == -1.0 && PyErr_Occurred())
            return NULL;
        if (k == n - 1) {
            if (t >= t0)
                return PySequence_GetItem(values, k);   /* the newest value, as it came */
        } else if (t0 <= t) {
            PyObject *a = PySequence_GetItem(values, k), *b = a ? PySequence_GetItem(values, k + 1) : NULL;
            if (!b) {
                Py_XDECREF(a);
                return NULL;
            }
            const double v0 = PyFloat_AsDouble(a), v1 = PyFloat_AsDouble(b);
            Py_DECREF(a);
            Py_DECREF(b);
            if (PyErr_Occurred())
                return NULL;
            const double w = t1 > t0 ? (t - t0) / (t1 - t0) : 1.0;
            return PyFloat_FromDouble(v0 + w * (v1 - v0));
        }
        t1 = t0;
    }
    return PySequence_GetItem(values, 0);   /* older than the whole series: its oldest value */
}

static PyObject *py_values_at(PyObject *self, PyObject *args)
{
    PyObject *lookups;
    double t;
    if (!PyArg_ParseTuple(args, "O!d", &PyTuple_Type, &lookups, &t))
        return NULL;
    const Py_ssize_t count = PyTuple_GET_SIZE(lookups);
    PyObject *out = PyTuple_New(count);
    if (!out)
        return NULL;
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *lookup = PyTuple_GET_ITEM(lookups, i), *value;
        if (lookup == Py_None) {
            value = Py_NewRef(Py_None);
        } else {
            PyObject *series, *name;
            if (!PyArg_ParseTuple(lookup, "O!O:values_at", &PyDict_Type, &series, &name)) {
                Py_DECREF(out);
                return NULL;
            }
            PyObject *pair = PyDict_GetItemWithError(series, name);
            if (!pair && PyErr_Occurred()) {
                Py_DECREF(out);
                return NULL;
            }
            value = pair ? value_at(pair, t) : Py_NewRef(Py_None);
            if (!value) {
                Py_DECREF(out);
                return NULL;
            }
        }
        PyTuple_SET_ITEM(out, i, value);
    }
    return out;
}

static PyObject *deque_append;   /* collections.deque.append, called on the series' deques */

/* _MessageHistory.push's loop: each value into `merged` and onto its (times, values) deques. */
static PyObject *py_push_values(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *series, *merged, *time_s, *values, *new_pair;
    if (!PyArg_ParseTuple(args, "O!O!O!O!O:push_values", &PyDict_Type, &series, &PyDict_Type, &merged,
                          &PyFloat_Type, &time_s, &PyDict_Type, &values, &new_pair))
        return NULL;
    Py_ssize_t pos = 0;
    PyObject *name, *value;
    while (PyDict_Next(values, &pos, &name, &value)) {
        if (PyDict_SetItem(merged, name, value) < 0)
            return NULL;
        PyObject *pair = PyDict_GetItemWithError(series, name);   /* borrowed */
        if (!pair) {
            if (PyErr_Occurred())
                return NULL;
            PyObject *fresh = PyObject_CallNoArgs(new_pair);
            if (!fresh)
                return NULL;
            const int stored = PyDict_SetItem(series, name, fresh);
            Py_DECREF(fresh);   /* (the dict holds it) */
            if (stored < 0)
                return NULL;
            pair = fresh;
        }
        if (!PyTuple_Check(pair) || PyTuple_GET_SIZE(pair) != 2) {
            PyErr_SetString(PyExc_TypeError, "push_values: a series is a (times, values) pair");
            return NULL;
        }
        PyObject *call_t[2] = {PyTuple_GET_ITEM(pair, 0), time_s}, *call_v[2] = {PyTuple_GET_ITEM(pair, 1), value};
        PyObject *r = PyObject_Vectorcall(deque_append, call_t, 2, NULL);
        if (!r)
            return NULL;
        Py_DECREF(r);
        if (!(r = PyObject_Vectorcall(deque_append, call_v, 2, NULL)))
            return NULL;
        Py_DECREF(r);
    }
    Py_RETURN_NONE;
}

static PyMethodDef methods[] = {
    {"fit_wheels", py_fit_wheels, METH_VARARGS,
     "fit_wheels(times, speeds, spike_threshold) -> (t_c, omega, omega_dot, glitch, torque_weights) | None\n\n"
     "FrontEnd._fit_wheels' closed-form quadratic fit; None for degenerate timestamps."},
    {"matched", py_matched, METH_VARARGS,
     "matched(ts, vs, times, weights, floor) -> float: FrontEnd._matched's weighted sum of a series\n"
     "interpolated at the window's times (floor: None, or subtracted and clipped at 0 per value)."},
    {"matched_many", py_matched_many, METH_VARARGS,
     "matched_many(lookups, times, weights) -> tuple: `matched` of each (series dict, name, floor or None)\n"
     "of lookups (or None); None for a signal without a series yet."},
    {"push_values", py_push_values, METH_VARARGS,
     "push_values(series, merged, time_s, values, new_pair) -> None: _MessageHistory.push's loop\n"
     "(new_pair() makes the (times, values) deques of a signal seen for the first time)."},
    {"values_at", py_values_at, METH_VARARGS,
     "values_at(lookups, t) -> tuple: for each (series dict, name) of lookups (or None), what\n"
     "_MessageHistory.value_at(t, name) gives: None when the signal has no series yet."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_frontcore",
                                    "The front end's per-sample numerics, compiled.", -1, methods,
                                    NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__frontcore(void)
{
    PyObject *collections = PyImport_ImportModule("collections");
    if (!collections)
        return NULL;
    PyObject *deque = PyObject_GetAttrString(collections, "deque");
    Py_DECREF(collections);
    if (!deque)
        return NULL;
    deque_append = PyObject_GetAttrString(deque, "append");
    Py_DECREF(deque);
    if (!deque_append)
        return NULL;
    return PyModule_Create(&module);
}
