/*
 * frictiond._frontcore: the front end's per-sample numerics, compiled.
 *
 * `FrontEnd._fit_wheels` (the derivative filter: a local quadratic fit of the four wheel
 * speeds over the window, its glitch test and the torque weights matched to it) and the
 * weighted sums of `FrontEnd._matched` (a signal interpolated at the window's times, weighted
 * as the filter weights the wheel's acceleration; several signals at once), the interpolation of
 * a sample's inputs (`MessageHistory.value_at`, batched) and `MessageHistory.push`'s loop
 * (each decoded value onto its signal's history), and the rest of a sample's physics
 * (`sample_physics`: `FrontEnd._compute_sample` from the inputs on). The Python code stays the reference and
 * the fallback where no compiler was available at install (tests compare the two).
 * Pure numerics: nothing of CAN, nothing of the tyre model.
 */
#include "_ccommon.h"
#include <math.h>

#define NW 4

/* wheel_speed_filter._glitch_value: whether sample k of one wheel's speeds y (n of them) disagrees, the
 * same way and by more than `threshold`, with its neighbours' interpolation and with each side's
 * own trend (a sensor glitch; a wheel turning around deep in slip follows each side's trend). */
static int glitch_at(const double *t, const double *y, Py_ssize_t n, Py_ssize_t k, double threshold)
{
    if (k < 2 || k + 2 >= n)
        return 0;
    const double t0 = t[k - 2], t1 = t[k - 1], t2 = t[k], t3 = t[k + 1], t4 = t[k + 2];
    if (!(t0 < t1 && t1 < t2 && t2 < t3 && t3 < t4))
        return 0;
    const double y0 = y[k - 2], y1 = y[k - 1], y2 = y[k], y3 = y[k + 1], y4 = y[k + 2];
    const double between = y1 + (y3 - y1) * (t2 - t1) / (t3 - t1);
    const double left = y1 + (y1 - y0) * (t2 - t1) / (t1 - t0);
    const double right = y3 - (y4 - y3) * (t3 - t2) / (t4 - t3);
    const double da = y2 - between, db = y2 - left, dc = y2 - right;
    return (da > threshold && db > threshold && dc > threshold)
           || (da < -threshold && db < -threshold && dc < -threshold);
}

/* wheel_speed_filter._quadratic_fit on times[lo, lo + m) and each wheel's speeds y[w * stride + k]: ω(t_c),
 * dω/dt(t_c) and the matched torque weights of those m samples (into weights[0, m)). 0 for
 * timestamps too degenerate for the closed form. scratch: 4 * (m + 1) doubles. */
static int quadratic_fit(const double *times, const double *y, Py_ssize_t stride, Py_ssize_t lo, Py_ssize_t m,
                         double t_c, double *omega, double *omega_dot, double *weights, double *scratch)
{
    double *u = scratch, *u2 = scratch + (m + 1), *c = scratch + 2 * (m + 1), *interval = scratch + 3 * (m + 1);
    const double *t = times + lo;
    double h = fmax(fabs(t[0] - t_c), fabs(t[m - 1] - t_c));
    if (h == 0.0)
        h = 1.0;
    for (Py_ssize_t k = 0; k < m; k++) {
        u[k] = (t[k] - t_c) / h;
        u2[k] = u[k] * u[k];
    }
    const double s1 = sum_of(u, m), s2 = sum_of(u2, m), s3 = dot_of(u, u2, m), s4 = dot_of(u2, u2, m);
    const double dn = (double)m;
    /* Symmetric 3x3 normal matrix [[n, s1, s2], [s1, s2, s3], [s2, s3, s4]]: its adjugate. */
    const double c00 = s2 * s4 - s3 * s3, c01 = s2 * s3 - s1 * s4, c02 = s1 * s3 - s2 * s2;
    const double c11 = dn * s4 - s2 * s2, c12 = s1 * s2 - dn * s3;
    const double det = dn * c00 + s1 * c01 + s2 * c02;
    if (!(det > 1e-9 * fmax(dn * s2 * s4, 1e-300)))
        return 0;
    const double inv = 1.0 / det;
    for (int w = 0; w < NW; w++) {
        const double *yw = y + w * stride + lo;
        const double b0 = sum_of(yw, m), b1 = dot_of(u, yw, m), b2 = dot_of(u2, yw, m);
        omega[w] = (c00 * b0 + c01 * b1 + c02 * b2) * inv;
        omega_dot[w] = (c01 * b0 + c11 * b1 + c12 * b2) * inv / h;
    }
    /* wheel_speed_filter._matched_weights with coef = (c01, c11, c12)·inv/h. */
    const double q0 = c01 * inv / h, q1 = c11 * inv / h, q2 = c12 * inv / h;
    for (Py_ssize_t k = 0; k < m; k++)
        c[k] = q0 + q1 * u[k] + q2 * u[k] * u[k];
    double tail = 0.0;
    for (Py_ssize_t k = 0; k <= m; k++)
        interval[k] = 0.0;
    for (Py_ssize_t j = m - 1; j > 0; j--) {
        tail += c[j];
        interval[j] = tail * (t[j] - t[j - 1]);
    }
    for (Py_ssize_t k = 0; k < m; k++)
        weights[k] = 0.5 * (interval[k] + interval[k + 1]);
    return 1;
}

/* fit_wheels(times, speeds, spike_threshold, torque_window)
 *   -> (t_c, omega, omega_dot, glitch, torque_weights, torque_omega_dot)
 * or None when the timestamps are too degenerate for the closed form (the caller then uses
 * least squares). `speeds`: one 4-sequence per time. FrontEnd._fit_window. */
static PyObject *py_fit_wheels(PyObject *self, PyObject *args)
{
    (void)self;
    PyObject *o_times, *o_speeds;
    double threshold;
    Py_ssize_t inner;
    if (!PyArg_ParseTuple(args, "OOdn:fit_wheels", &o_times, &o_speeds, &threshold, &inner))
        return NULL;
    Py_ssize_t n;
    double *times = floats_of(o_times, &n, "times");
    if (!times)
        return NULL;
    double *buf = PyMem_Malloc((size_t)(6 * (n + 1) + NW * (n + 1)) * sizeof(double));
    PyObject *seq = NULL, *result = NULL;
    if (!buf) {
        PyErr_NoMemory();
        goto out;
    }
    double *scratch = buf, *weights = buf + 4 * (n + 1), *inner_weights = buf + 5 * (n + 1);
    double *y = buf + 6 * (n + 1);   /* y[w * (n + 1) + k] */
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
    double omega[NW], omega_dot[NW], inner_omega[NW], torque_omega_dot[NW];
    if (!quadratic_fit(times, y, n + 1, 0, n, t_c, omega, omega_dot, weights, scratch)) {
        result = Py_None;
        Py_INCREF(result);
        goto out;
    }
    double *torque_weights = weights;
    for (int w = 0; w < NW; w++)
        torque_omega_dot[w] = omega_dot[w];
    if (inner >= 3 && inner < n) {
        const Py_ssize_t lo = (n - inner) / 2;
        for (Py_ssize_t k = 0; k < n; k++)
            inner_weights[k] = 0.0;
        /* (a degenerate inner fit returns before writing: the whole window's ω̇ and weights stay) */
        if (quadratic_fit(times, y, n + 1, lo, inner, t_c, inner_omega, torque_omega_dot, inner_weights + lo,
                          scratch))
            torque_weights = inner_weights;
    }
    int glitch = 0;
    for (int w = 0; w < NW && !glitch; w++)
        glitch = glitch_at(times, y + w * (n + 1), n, n - 3, threshold);
    {
        PyObject *a = tuple_of(omega, NW), *b = a ? tuple_of(omega_dot, NW) : NULL;
        PyObject *wt = b ? tuple_of(torque_weights, n) : NULL, *td = wt ? tuple_of(torque_omega_dot, NW) : NULL;
        if (td)
            result = Py_BuildValue("(dNNONN)", t_c, a, b, glitch ? Py_True : Py_False, wt, td);
        else {
            Py_XDECREF(a);
            Py_XDECREF(b);
            Py_XDECREF(wt);
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
 * input_alignment.interpolation_plan; with a floor, each series value v counts as max(0, v − floor). */
/* One walk of interpolation_plan over the series ts[0..ns) at the window's times and weights w,
 * its coefficients into coef (zeroed, seen zeroed), summed in the order first touched: Σ w·value,
 * each value less floor_value and clipped at 0 when has_floor; with `slopes`, Σ w·slope instead
 * (interpolation_plan(..., slopes=True): 0 beyond its ends and across a repeated time). */
static double plan_sum(const double *ts, const double *vs, Py_ssize_t ns, const double *times, const double *w,
                       Py_ssize_t nt, int has_floor, double floor_value, int slopes, double *coef, Py_ssize_t *order,
                       char *seen)
{
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
            if (!slopes)
                ADD(last, wt);
            continue;
        }
        while (k > 0 && ts[k - 1] > t)
            k--;
        if (k == 0) {
            if (!slopes)
                ADD(0, wt);
            continue;
        }
        const double t0 = ts[k - 1], t1 = ts[k];
        if (slopes) {
            if (t1 > t0) {
                ADD(k - 1, -(wt / (t1 - t0)));
                ADD(k, wt / (t1 - t0));
            }
            continue;
        }
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
    return total;
}

/* FrontEnd._matched of one series (o_ts, o_vs) over the window's times and weights: *total_out
 * (each value less floor_value and clipped at 0 when has_floor). With slope_out, from the same
 * reading of the series, its slopes so matched too (InputAlignment._matched_brake_rates) into
 * *slope_out where it has two frames or more. 1 when *slope_out was set, else 0; -1 with an
 * exception. */
static int matched_sum(PyObject *o_ts, PyObject *o_vs, const double *times, const double *w, Py_ssize_t nt,
                       int has_floor, double floor_value, double *total_out, double *slope_out)
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
    *total_out = plan_sum(ts, vs, ns, times, w, nt, has_floor, floor_value, 0, coef, order, seen);
    status = 0;
    if (slope_out && ns >= 2) {
        memset(coef, 0, (size_t)ns * sizeof(double));
        memset(seen, 0, (size_t)ns);
        *slope_out = plan_sum(ts, vs, ns, times, w, nt, has_floor, floor_value, 1, coef, order, seen);
        status = 1;
    }
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
        && matched_sum(o_ts, o_vs, times, w, nt, has_floor, floor_value, &total, NULL) == 0)
        result = PyFloat_FromDouble(total);
    PyMem_Free(times);
    PyMem_Free(w);
    return result;
}

/* One (series dict, name, floor or None) lookup of matched_many: *pair its (times, values) series
 * (NULL: none yet), *has_floor and *floor_value its floor. 0, or -1 with an exception. */
static int lookup_series(PyObject *lookup, const char *who, PyObject **pair, int *has_floor, double *floor_value)
{
    PyObject *series, *name, *o_floor;
    *pair = NULL;
    if (!PyArg_ParseTuple(lookup, "O!OO", &PyDict_Type, &series, &name, &o_floor))
        return -1;
    *has_floor = o_floor != Py_None;
    *floor_value = 0.0;
    if (*has_floor && (*floor_value = PyFloat_AsDouble(o_floor)) == -1.0 && PyErr_Occurred())
        return -1;
    if (!(*pair = PyDict_GetItemWithError(series, name)))
        return PyErr_Occurred() ? -1 : 0;
    if (!PyTuple_Check(*pair) || PyTuple_GET_SIZE(*pair) != 2) {
        PyErr_Format(PyExc_TypeError, "%s: a series is a (times, values) pair", who);
        return -1;
    }
    return 0;
}

/* matched_many over the window's times and weights (nt of them): a tuple of float | None. With
 * n_slopes, in the same pass, the first n_slopes lookups' series' matched slopes times gains[i]
 * into rates[i] where a series has two frames or more (have[i] = 1; else 0):
 * InputAlignment._matched_brake_rates. NULL with an exception. */
static PyObject *matched_lookups(PyObject *lookups, const double *times, const double *w, Py_ssize_t nt,
                                 Py_ssize_t n_slopes, const double *gains, double *rates, int *have)
{
    const Py_ssize_t count = PyTuple_GET_SIZE(lookups);
    if (count < n_slopes) {
        PyErr_SetString(PyExc_ValueError, "matched_many: too few lookups for their slopes");
        return NULL;
    }
    PyObject *out = PyTuple_New(count);
    if (!out)
        return NULL;
    for (Py_ssize_t i = 0; i < count; i++) {
        PyObject *lookup = PyTuple_GET_ITEM(lookups, i), *pair, *value = NULL;
        if (i < n_slopes)
            have[i] = 0;
        if (lookup == Py_None) {
            PyTuple_SET_ITEM(out, i, Py_NewRef(Py_None));
            continue;
        }
        int has_floor;
        double floor_value, total = 0.0, slope = 0.0;
        if (lookup_series(lookup, "matched_many", &pair, &has_floor, &floor_value) < 0)
            goto fail;
        if (!pair) {
            value = Py_NewRef(Py_None);   /* no series yet: the caller's fallback */
        } else {
            const int sloped = matched_sum(PyTuple_GET_ITEM(pair, 0), PyTuple_GET_ITEM(pair, 1), times, w, nt,
                                           has_floor, floor_value, &total, i < n_slopes ? &slope : NULL);
            if (sloped < 0 || !(value = PyFloat_FromDouble(total)))
                goto fail;
            if (sloped) {
                rates[i] = gains[i] * slope;
                have[i] = 1;
            }
        }
        PyTuple_SET_ITEM(out, i, value);
    }
    return out;
fail:
    Py_DECREF(out);
    return NULL;
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
    if (window_of(o_times, o_w, &times, &w, &nt) == 0)
        out = matched_lookups(lookups, times, w, nt, 0, NULL, NULL, NULL);
    PyMem_Free(times);
    PyMem_Free(w);
    return out;
}

/* MessageHistory.value_at for one signal: its (times, values) deques at time t; a new reference. */
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

/* MessageHistory.push's loop: each value into `merged` and onto its (times, values) deques. */
/* METH_FASTCALL (once per input frame: PyArg_ParseTuple's format cost as much as the loop). */
static PyObject *py_push_values(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (nargs != 5) {
        PyErr_Format(PyExc_TypeError, "push_values() takes 5 arguments (%zd given)", nargs);
        return NULL;
    }
    PyObject *series = args[0], *merged = args[1], *time_s = args[2], *values = args[3], *new_pair = args[4];
    if (!PyDict_Check(series) || !PyDict_Check(merged) || !PyFloat_Check(time_s) || !PyDict_Check(values)) {
        PyErr_SetString(PyExc_TypeError, "push_values(series: dict, merged: dict, time_s: float, values: dict, new_pair)");
        return NULL;
    }
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

/* ---------------------------------------------------------------------------------------------
 * sample_physics: FrontEnd._compute_sample after the fit and the inputs' interpolation (the
 * range checks, dead and stuck wheels, the speed observer, the accelerometer offset, the load
 * transfer, the brake-gain check against the body equation and each wheel's slip and μ), on the
 * FrontEnd's own attributes. Each step mirrors its Python method line by line, including
 * Python's min/max on NaN (the first argument is kept unless the second compares beyond it).
 */

/* The per-sample constants, in the order of FrontEnd._physics_constants. */
enum {
    K_STUCK_FRAMES, K_PUSHOUT, K_MIN_BRAKE_PRESSURE, K_MIN_SPEED, K_DEAD_RATIO, K_DEAD_S, K_DEAD_UNBRAKED_S,
    K_MAX_GAP, K_UNEXPLAINED_DECEL, K_RADIUS, K_GAIN_FREE, K_GAIN_UP, K_GAIN_DOWN, K_MIN_BRAKED_SLIP,
    K_MAX_ALL_WHEEL_SLIP, K_SAMPLE_PERIOD, K_BIAS_TAU, K_MASS, K_CG_HEIGHT, K_CG_FRONT, K_CG_REAR, K_TRACK_FRONT,
    K_TRACK_REAR, K_INERTIA, K_GAIN_CORRECTION, K_GAIN_MIN_DECEL, K_ROLLING, K_DRAG, K_GAIN_LIMITS, K_GAIN_TAU,
    K_MAX_SLIP, K_HAS_DRIVE, K_HAS_YAW, K_MASTER_ONLY, K_BRAKE_GAIN_FL, K_BRAKE_GAIN_FR, K_BRAKE_GAIN_RL, K_BRAKE_GAIN_RR,
    K_LAG_COMPENSATION, K_BIAS_SETTLE, K_CORRECTION_RATE, K_CORRECTION_HOLD, K_DRAG_DOUBT, K_WIND_DOUBT, K_LEVEL_ROAD,
    K_ACCEL_TOLERANCE, K_COASTING_OFFSET, K_RELEASED_S, K_RELEASED_MIN_SLIP, K_COUNT
};

#define MAX_ABS_ACCEL 30.0
#define MAX_PRESSURE 350.0
#define MAX_SPEED 120.0
#define FREE_ROLLING_SPREAD 0.04
#define FREE_ROLLING_ACCEL 2.0
#define SETTLE_SLIP 0.01
#define BRAKE_MODEL_MARGIN 1.25
#define BRAKE_MODEL_WINDOW 0.2
#define LOCKED_WHEEL_RATIO 0.05
#define BODY_ACCEL_TOLERANCE 0.05
#define PRESSURE_TOLERANCE 0.25
#define FAULT_WIND 5.0           /* body_equation.FAULT_WIND_MPS */
#define ACCEL_BIAS_LEARNT_SAMPLES 50
#define ACCEL_BIAS_PRIOR_SAMPLES 2.0
#define SENSOR_OFFSET_PRIOR_S 0.2      /* brake_gain.SENSOR_OFFSET_PRIOR_S */
#define SENSOR_OFFSET_LIMIT 1.0        /* brake_gain.SENSOR_OFFSET_LIMIT_MPS2 */
#define PRESSURE_SENSOR_LAG 0.04
#define MAX_PRESSURE_LAG 0.05
#define MIN_PRESSURE_LAG 0.002
#define PRESSURE_LAG_TIME_CONSTANT 5.0
#define PRESSURE_LAG_PRIOR (10 * 10000.0 * 10000.0)
/* FrontEnd._lag_state: the lag regression's five sums, the lag, the last sample's time and torques. */
#define LAG_N 11
#define LAG_LAG 5
#define LAG_TIME 6
#define LAG_TORQUES 7
#define GRAVITY 9.80665

/* The FrontEnd attributes sample_physics reads and writes. */
static PyObject *A_repeats, *A_dead, *A_low_since, *A_low_unbraked, *A_braked_time, *A_last_sample, *A_bias, *A_bias_samples, *A_bias_m2,
    *A_unexplained, *A_speed_time, *A_speed_est, *A_ref_disagreements, *A_gain_tt, *A_gain_tn, *A_gain_t, *A_gain_n,
    *A_gain_w, *A_sensed_needed, *A_sensed_needed_time, *A_sensor_offset, *A_sensor_offset_doubt,
    *A_recent_lag, *A_last_brake, *A_recent_weight, *A_recent_needed, *A_recent_brake, *A_gain_factor, *A_gain_doubt, *A_model_holds, *A_released,
    *A_unjudged, *A_lag_state, *A_slipping_time, *A_faster_since, *A_restarted_braking, *A_rolling_offset,
    *A_rolling_samples, *A_rolling_m2, *A_rolling_air, *A_free_rolling;

typedef struct {
    long repeats[NW];
    int dead[NW];
    int has_low_since[NW];
    double low_since[NW], low_unbraked[NW], braked_time[NW];
    int has_last_sample, has_speed_time, has_speed_est, has_faster_since, restarted_braking;
    double last_sample, bias, unexplained, speed_time, speed_est, slipping_time, faster_since;
    long bias_samples, ref_disagreements, rolling_samples;
    double bias_m2, rolling_offset, rolling_m2, rolling_air;
    double sensed_needed, sensed_needed_time;
    double gain_tt, gain_tn, gain_t, gain_n, gain_w, sensor_offset, sensor_offset_doubt, recent_lag, last_brake, recent_weight, recent_needed, recent_brake, gain_factor, gain_doubt;
    double unjudged;
    int model_holds, released;
    int free_rolling;   /* (written only: whether this sample rolled free, `_free_rolling_sample`) */
    double lag[LAG_N];
} FEState;

static int get_float_attr(PyObject *obj, PyObject *name, double *out, int *present)
{
    PyObject *v = PyObject_GetAttr(obj, name);
    if (!v)
        return -1;
    if (present && v == Py_None) {
        *present = 0;
        *out = 0.0;
        Py_DECREF(v);
        return 0;
    }
    *out = PyFloat_AsDouble(v);
    Py_DECREF(v);
    if (*out == -1.0 && PyErr_Occurred())
        return -1;
    if (present)
        *present = 1;
    return 0;
}

static int get_long_attr(PyObject *obj, PyObject *name, long *out)
{
    PyObject *v = PyObject_GetAttr(obj, name);
    if (!v)
        return -1;
    *out = PyLong_AsLong(v);
    Py_DECREF(v);
    return (*out == -1 && PyErr_Occurred()) ? -1 : 0;
}

static int get_bool_attr(PyObject *obj, PyObject *name, int *out)
{
    PyObject *v = PyObject_GetAttr(obj, name);
    if (!v)
        return -1;
    *out = PyObject_IsTrue(v);
    Py_DECREF(v);
    return *out < 0 ? -1 : 0;
}

/* A 4-list attribute (the per-wheel state lists): a new reference, or NULL with an exception. */
static PyObject *list_attr(PyObject *obj, PyObject *name)
{
    PyObject *v = PyObject_GetAttr(obj, name);
    if (!v)
        return NULL;
    if (!PyList_Check(v) || PyList_GET_SIZE(v) != NW) {
        PyErr_Format(PyExc_TypeError, "sample_physics: %U must be a list of four", name);
        Py_DECREF(v);
        return NULL;
    }
    return v;
}

static int load_state(PyObject *fe, FEState *s)
{
    s->free_rolling = 0;
    PyObject *repeats = NULL, *dead = NULL, *since = NULL, *unbraked = NULL, *braked_time = NULL;
    int rc = -1;
    if (!(repeats = list_attr(fe, A_repeats)) || !(dead = list_attr(fe, A_dead)) || !(since = list_attr(fe, A_low_since))
        || !(unbraked = list_attr(fe, A_low_unbraked)) || !(braked_time = list_attr(fe, A_braked_time)))
        goto out;
    for (int i = 0; i < NW; i++) {
        if ((s->repeats[i] = PyLong_AsLong(PyList_GET_ITEM(repeats, i))) == -1 && PyErr_Occurred())
            goto out;
        if ((s->dead[i] = PyObject_IsTrue(PyList_GET_ITEM(dead, i))) < 0)
            goto out;
        PyObject *t = PyList_GET_ITEM(since, i);
        s->has_low_since[i] = t != Py_None;
        s->low_since[i] = s->has_low_since[i] ? PyFloat_AsDouble(t) : 0.0;
        s->low_unbraked[i] = PyFloat_AsDouble(PyList_GET_ITEM(unbraked, i));
        s->braked_time[i] = PyFloat_AsDouble(PyList_GET_ITEM(braked_time, i));
        if (PyErr_Occurred())
            goto out;
    }
    if (get_float_attr(fe, A_last_sample, &s->last_sample, &s->has_last_sample) < 0
        || get_float_attr(fe, A_bias, &s->bias, NULL) < 0 || get_long_attr(fe, A_bias_samples, &s->bias_samples) < 0
        || get_float_attr(fe, A_bias_m2, &s->bias_m2, NULL) < 0
        || get_float_attr(fe, A_rolling_offset, &s->rolling_offset, NULL) < 0
        || get_long_attr(fe, A_rolling_samples, &s->rolling_samples) < 0
        || get_float_attr(fe, A_rolling_m2, &s->rolling_m2, NULL) < 0
        || get_float_attr(fe, A_rolling_air, &s->rolling_air, NULL) < 0
        || get_float_attr(fe, A_slipping_time, &s->slipping_time, NULL) < 0
        || get_float_attr(fe, A_unexplained, &s->unexplained, NULL) < 0
        || get_float_attr(fe, A_speed_time, &s->speed_time, &s->has_speed_time) < 0
        || get_float_attr(fe, A_speed_est, &s->speed_est, &s->has_speed_est) < 0
        || get_float_attr(fe, A_faster_since, &s->faster_since, &s->has_faster_since) < 0
        || get_bool_attr(fe, A_restarted_braking, &s->restarted_braking) < 0
        || get_long_attr(fe, A_ref_disagreements, &s->ref_disagreements) < 0
        || get_float_attr(fe, A_gain_tt, &s->gain_tt, NULL) < 0 || get_float_attr(fe, A_gain_tn, &s->gain_tn, NULL) < 0
        || get_float_attr(fe, A_gain_t, &s->gain_t, NULL) < 0 || get_float_attr(fe, A_gain_n, &s->gain_n, NULL) < 0
        || get_float_attr(fe, A_gain_w, &s->gain_w, NULL) < 0
        || get_float_attr(fe, A_sensed_needed, &s->sensed_needed, NULL) < 0
        || get_float_attr(fe, A_sensed_needed_time, &s->sensed_needed_time, NULL) < 0
        || get_float_attr(fe, A_sensor_offset, &s->sensor_offset, NULL) < 0
        || get_float_attr(fe, A_sensor_offset_doubt, &s->sensor_offset_doubt, NULL) < 0
        || get_float_attr(fe, A_recent_weight, &s->recent_weight, NULL) < 0
        || get_float_attr(fe, A_recent_lag, &s->recent_lag, NULL) < 0
        || get_float_attr(fe, A_last_brake, &s->last_brake, NULL) < 0
        || get_float_attr(fe, A_recent_needed, &s->recent_needed, NULL) < 0
        || get_float_attr(fe, A_recent_brake, &s->recent_brake, NULL) < 0
        || get_bool_attr(fe, A_released, &s->released) < 0
        || get_float_attr(fe, A_gain_factor, &s->gain_factor, NULL) < 0
        || get_float_attr(fe, A_gain_doubt, &s->gain_doubt, NULL) < 0
        || get_bool_attr(fe, A_model_holds, &s->model_holds) < 0
        || get_float_attr(fe, A_unjudged, &s->unjudged, NULL) < 0)
        goto out;
    PyObject *lag = PyObject_GetAttr(fe, A_lag_state);
    if (!lag)
        goto out;
    if (!PyTuple_Check(lag) || PyTuple_GET_SIZE(lag) != LAG_N) {
        PyErr_SetString(PyExc_TypeError, "sample_physics: _lag_state must be a tuple of eleven");
        Py_DECREF(lag);
        goto out;
    }
    for (int i = 0; i < LAG_N; i++)
        s->lag[i] = PyFloat_AsDouble(PyTuple_GET_ITEM(lag, i));
    Py_DECREF(lag);
    if (PyErr_Occurred())
        goto out;
    rc = 0;
out:
    Py_XDECREF(repeats);
    Py_XDECREF(dead);
    Py_XDECREF(since);
    Py_XDECREF(unbraked);
    Py_XDECREF(braked_time);
    return rc;
}

/* obj.name = value (a new reference, consumed; NULL passes the error on). */
static int set_attr_new(PyObject *obj, PyObject *name, PyObject *value)
{
    if (!value)
        return -1;
    const int rc = PyObject_SetAttr(obj, name, value);
    Py_DECREF(value);
    return rc;
}

static PyObject *float_or_none(int present, double v)
{
    return present ? PyFloat_FromDouble(v) : Py_NewRef(Py_None);
}

/* What sample_physics changed, written back (the lists in place, as the Python code does). */
static int store_state(PyObject *fe, const FEState *s)
{
    PyObject *dead = NULL, *since = NULL, *unbraked = NULL, *braked_time = NULL;
    int rc = -1;
    if (!(dead = list_attr(fe, A_dead)) || !(since = list_attr(fe, A_low_since))
        || !(unbraked = list_attr(fe, A_low_unbraked)) || !(braked_time = list_attr(fe, A_braked_time)))
        goto out;
    for (int i = 0; i < NW; i++) {
        PyObject *t = float_or_none(s->has_low_since[i], s->low_since[i]), *u = PyFloat_FromDouble(s->low_unbraked[i]);
        PyObject *b = PyFloat_FromDouble(s->braked_time[i]);
        if (!t || !u || !b) {
            Py_XDECREF(t);
            Py_XDECREF(u);
            Py_XDECREF(b);
            goto out;
        }
        PyList_SetItem(dead, i, PyBool_FromLong(s->dead[i]));
        PyList_SetItem(since, i, t);
        PyList_SetItem(unbraked, i, u);
        PyList_SetItem(braked_time, i, b);
    }
    if (set_attr_new(fe, A_last_sample, float_or_none(s->has_last_sample, s->last_sample)) < 0
        || set_attr_new(fe, A_bias, PyFloat_FromDouble(s->bias)) < 0
        || set_attr_new(fe, A_bias_samples, PyLong_FromLong(s->bias_samples)) < 0
        || set_attr_new(fe, A_bias_m2, PyFloat_FromDouble(s->bias_m2)) < 0
        || set_attr_new(fe, A_rolling_offset, PyFloat_FromDouble(s->rolling_offset)) < 0
        || set_attr_new(fe, A_rolling_samples, PyLong_FromLong(s->rolling_samples)) < 0
        || set_attr_new(fe, A_rolling_m2, PyFloat_FromDouble(s->rolling_m2)) < 0
        || set_attr_new(fe, A_rolling_air, PyFloat_FromDouble(s->rolling_air)) < 0
        || set_attr_new(fe, A_slipping_time, PyFloat_FromDouble(s->slipping_time)) < 0
        || set_attr_new(fe, A_free_rolling, PyBool_FromLong(s->free_rolling)) < 0
        || set_attr_new(fe, A_unexplained, PyFloat_FromDouble(s->unexplained)) < 0
        || set_attr_new(fe, A_speed_time, float_or_none(s->has_speed_time, s->speed_time)) < 0
        || set_attr_new(fe, A_speed_est, float_or_none(s->has_speed_est, s->speed_est)) < 0
        || set_attr_new(fe, A_faster_since, float_or_none(s->has_faster_since, s->faster_since)) < 0
        || set_attr_new(fe, A_restarted_braking, PyBool_FromLong(s->restarted_braking)) < 0
        || set_attr_new(fe, A_ref_disagreements, PyLong_FromLong(s->ref_disagreements)) < 0
        || set_attr_new(fe, A_gain_tt, PyFloat_FromDouble(s->gain_tt)) < 0
        || set_attr_new(fe, A_gain_tn, PyFloat_FromDouble(s->gain_tn)) < 0
        || set_attr_new(fe, A_gain_t, PyFloat_FromDouble(s->gain_t)) < 0
        || set_attr_new(fe, A_gain_n, PyFloat_FromDouble(s->gain_n)) < 0
        || set_attr_new(fe, A_gain_w, PyFloat_FromDouble(s->gain_w)) < 0
        || set_attr_new(fe, A_sensed_needed, PyFloat_FromDouble(s->sensed_needed)) < 0
        || set_attr_new(fe, A_sensed_needed_time, PyFloat_FromDouble(s->sensed_needed_time)) < 0
        || set_attr_new(fe, A_sensor_offset, PyFloat_FromDouble(s->sensor_offset)) < 0
        || set_attr_new(fe, A_sensor_offset_doubt, PyFloat_FromDouble(s->sensor_offset_doubt)) < 0
        || set_attr_new(fe, A_recent_weight, PyFloat_FromDouble(s->recent_weight)) < 0
        || set_attr_new(fe, A_recent_lag, PyFloat_FromDouble(s->recent_lag)) < 0
        || set_attr_new(fe, A_last_brake, PyFloat_FromDouble(s->last_brake)) < 0
        || set_attr_new(fe, A_recent_needed, PyFloat_FromDouble(s->recent_needed)) < 0
        || set_attr_new(fe, A_recent_brake, PyFloat_FromDouble(s->recent_brake)) < 0
        || set_attr_new(fe, A_released, PyBool_FromLong(s->released)) < 0
        || set_attr_new(fe, A_gain_factor, PyFloat_FromDouble(s->gain_factor)) < 0
        || set_attr_new(fe, A_gain_doubt, PyFloat_FromDouble(s->gain_doubt)) < 0
        || set_attr_new(fe, A_model_holds, PyBool_FromLong(s->model_holds)) < 0
        || set_attr_new(fe, A_unjudged, PyFloat_FromDouble(s->unjudged)) < 0
        || set_attr_new(fe, A_lag_state, tuple_of(s->lag, LAG_N)) < 0)
        goto out;
    rc = 0;
out:
    Py_XDECREF(dead);
    Py_XDECREF(since);
    Py_XDECREF(unbraked);
    Py_XDECREF(braked_time);
    return rc;
}

/* FrontEnd._dead_wheels */
static void dead_wheels(FEState *s, const double *k, double time_s, const double *wl, const int *braked, int *out)
{
    for (int i = 0; i < NW; i++) {
        double others = 0.0;
        int first = 1;
        for (int j = 0; j < NW; j++) {
            if (j == i)
                continue;
            others = first ? wl[j] : py_max(others, wl[j]);
            first = 0;
        }
        const double w = wl[i];
        out[i] = 0;
        if (s->dead[i]) {
            if (w > 0.5 * others && w > 0.3) {
                s->dead[i] = 0;
                s->has_low_since[i] = 0;
                s->low_unbraked[i] = 0.0;
            }
            out[i] = s->dead[i];
            continue;
        }
        const int low = others >= k[K_MIN_SPEED] && w < k[K_DEAD_RATIO] * others;
        if (!low) {
            s->has_low_since[i] = 0;
            s->low_unbraked[i] = 0.0;
            continue;
        }
        double since = s->low_since[i];
        if (!s->has_low_since[i] || time_s < since) {
            s->has_low_since[i] = 1;
            s->low_since[i] = since = time_s;
            s->low_unbraked[i] = 0.0;
        } else if (!braked[i] && s->has_last_sample) {
            s->low_unbraked[i] += py_max(0.0, py_min(time_s - s->last_sample, k[K_MAX_GAP]));
        }
        if (time_s - since > k[K_DEAD_S] || s->low_unbraked[i] > k[K_DEAD_UNBRAKED_S])
            s->dead[i] = out[i] = 1;
    }
}

/* FrontEnd._ref_plausible */
static int ref_plausible(FEState *s, const double *k, double ref, double fastest)
{
    if (ref + 1.0 < fastest * 0.95)
        return 0;
    if (ref > fastest / (1.0 - k[K_MAX_ALL_WHEEL_SLIP]) + 1.0 && fastest >= 0.5)
        return 0;
    if (s->has_speed_est && fabs(ref - s->speed_est) > 1.0 + 0.1 * s->speed_est) {
        s->ref_disagreements += 1;
        return s->ref_disagreements > 10;
    }
    s->ref_disagreements = 0;
    return 1;
}

/* FrontEnd._update_speed; `ref_fresh` is `_ref_fresh(time_s)` (the reference is None when absent). */
/* speed_estimate._second_fastest: the second-largest of the four wheels' speeds */
static double second_of(const double *wl)
{
    double first = -INFINITY, second = -INFINITY;
    for (int i = 0; i < NW; i++) {
        if (wl[i] > first) {
            second = first;
            first = wl[i];
        } else if (wl[i] > second)
            second = wl[i];
    }
    return second;
}

static double update_speed(FEState *s, const double *k, double time_s, const double *wl, double accel_long,
                           int wheels_loaded, int has_ref, double ref, int ref_fresh, int *from_ref)
{
    const double dt = s->has_speed_time ? time_s - s->speed_time : 0.0;
    s->has_speed_time = 1;
    s->speed_time = time_s;
    double fastest = wl[0];
    for (int i = 1; i < NW; i++)
        fastest = py_max(fastest, wl[i]);
    *from_ref = 0;
    const int was_faster = s->has_faster_since;   /* (two wheels faster than it, since) */
    s->has_faster_since = 0;
    if (has_ref && ref_fresh && 0.0 <= ref && ref <= MAX_SPEED && ref_plausible(s, k, ref, fastest)) {
        s->has_speed_est = 1;
        s->speed_est = ref;
        *from_ref = 1;
        return ref;
    }
    const double mean = sum_of(wl, NW) / 4.0;
    double v = s->speed_est;
    if (!s->has_speed_est || dt <= 0.0 || dt > k[K_MAX_GAP]) {
        v = fastest;
        s->restarted_braking = wheels_loaded;   /* (from a slipping wheel) */
    } else {
        v = v + accel_long * dt;
        const double second = second_of(wl);
        if (!wheels_loaded) {
            v += k[K_GAIN_FREE] * (mean - v);
            s->restarted_braking = 0;
        } else if (second > v) {
            s->has_faster_since = 1;
            s->faster_since = was_faster ? s->faster_since : time_s;
            const int full = time_s - s->faster_since >= k[K_CORRECTION_HOLD] || s->restarted_braking;
            const double limit = full ? MAX_ABS_ACCEL * 0.5 * dt + 0.02 : k[K_CORRECTION_RATE] * dt;
            v += py_min(k[K_GAIN_UP] * (second - v), limit);
        } else {
            const double ceiling = fastest / (1.0 - k[K_MIN_BRAKED_SLIP]);
            if (v > ceiling)
                v -= py_min(k[K_GAIN_DOWN] * (v - ceiling), k[K_CORRECTION_RATE] * dt);
        }
    }
    v = py_min(py_max(v, 0.0), MAX_SPEED);
    s->has_speed_est = 1;
    s->speed_est = v;
    return v;
}

/* FrontEnd._brake_torque_rates: each wheel's matched brake torque's rate since the last sample. */
static void brake_torque_rates(FEState *s, const double *k, double time_s, const double *torques, double *rates)
{
    const double dt = time_s - s->lag[LAG_TIME];   /* (NaN before the first sample: no rate) */
    const int ok = 0.0 < dt && dt <= k[K_MAX_GAP];
    for (int i = 0; i < NW; i++) {
        const double rate = ok ? (torques[i] - s->lag[LAG_TORQUES + i]) / dt : 0.0;
        rates[i] = isfinite(rate) ? rate : 0.0;
        s->lag[LAG_TORQUES + i] = torques[i];
    }
    s->lag[LAG_TIME] = time_s;
}

/* FrontEnd._learn_pressure_lag: N = k·(B + τ·Ḃ) fitted by least squares with forgetting. */
static void learn_pressure_lag(FEState *s, const double *k, double brake, double rate, double needed)
{
    const double keep = 1.0 - py_min(1.0, k[K_SAMPLE_PERIOD] / PRESSURE_LAG_TIME_CONSTANT);
    const double s_bb = keep * s->lag[0] + brake * brake, s_bd = keep * s->lag[1] + brake * rate;
    const double s_dd = keep * s->lag[2] + rate * rate, s_bn = keep * s->lag[3] + brake * needed;
    const double s_dn = keep * s->lag[4] + rate * needed;
    if (!(isfinite(s_bb) && isfinite(s_bd) && isfinite(s_dd) && isfinite(s_bn) && isfinite(s_dn)))
        return;   /* a NaN here would stay in the sums for good */
    const double dd = s_dd + PRESSURE_LAG_PRIOR;
    const double det = s_bb * dd - s_bd * s_bd;
    if (det > 0.0) {
        const double gain = (s_bn * dd - s_bd * s_dn) / det, k_lag = (s_bb * s_dn - s_bd * s_bn) / det;
        if (0.5 < gain && gain < 2.0) {
            const double lag = py_min(py_max(k_lag / gain, 0.0), MAX_PRESSURE_LAG);
            s->lag[LAG_LAG] = lag >= MIN_PRESSURE_LAG ? lag : 0.0;
        }
    }
    s->lag[0] = s_bb, s->lag[1] = s_bd, s->lag[2] = s_dd, s->lag[3] = s_bn, s->lag[4] = s_dn;
}

/* free_rolling_offset.spread_variance: offset samples' variance with a prior of a few spread by the tolerance. */
static double spread_variance(long samples, double sum_squares, double tolerance)
{
    return (sum_squares + ACCEL_BIAS_PRIOR_SAMPLES * tolerance * tolerance)
           / ((double)(samples > 1 ? samples - 1 : 0) + ACCEL_BIAS_PRIOR_SAMPLES);
}

/* VehicleParams.resistance_doubt_n: how much more drag than configured the car may meet at
 * `speed` in a head wind of `wind`. */
static double resistance_doubt(const double *k, double speed, double wind)
{
    const double air = speed + wind;
    return k[K_DRAG_DOUBT] * air * air + k[K_DRAG] * wind * (speed + air);
}

/* free_rolling_offset.offset_doubt_mps2: what the offset learnt from free rolling may still be off by. */
static double offset_doubt(long samples, double sum_squares, double tolerance)
{
    if (samples >= ACCEL_BIAS_LEARNT_SAMPLES)
        return 0.0;
    return py_min(tolerance, sqrt(3.0 * spread_variance(samples, sum_squares, tolerance)
                                  / (double)(samples > 1 ? samples : 1)));
}

/* body_equation.BodyEquation.rolling_offset_prior: free rolling's offset (*mean) and its
 * half-width (returned). */
static double rolling_offset_prior(const FEState *s, const double *k, double *mean)
{
    const double tolerance = k[K_ACCEL_TOLERANCE];
    *mean = 0.0;
    if (s->rolling_samples == 0)
        return tolerance;
    const double remembered = py_min((double)s->rolling_samples, py_max(k[K_BIAS_TAU], 1e-3) / k[K_SAMPLE_PERIOD]);
    const double variance = spread_variance(s->rolling_samples, s->rolling_m2, tolerance);
    const double width = sqrt(3.0 * variance / remembered) + s->rolling_air;
    *mean = py_min(py_max(s->rolling_offset, -tolerance), tolerance);
    return py_min(tolerance, py_max(BODY_ACCEL_TOLERANCE, width));
}

/* brake_gain.gain_and_sensor_offset: the brake gain (returned) and the accelerometer's offset
 * (*offset) of N = G·T − M·R·s by least squares with a prior of s = prior_offset (half-width
 * prior_width), and what s may be off by. */
static double gain_and_sensor_offset(const FEState *s, double prior_samples, double mass_radius, double tolerance,
                                     double prior_offset, double prior_width, double *offset, double *doubt)
{
    const double width = py_min(py_max(prior_width, 1e-6), tolerance);
    const double weight = prior_samples * (tolerance / width) * (tolerance / width);
    const double a11 = s->gain_tt, a12 = s->gain_t, a22 = s->gain_w + weight;
    const double det = a11 * a22 - a12 * a12;
    if (!(det > 0.0 && isfinite(det))) {
        *offset = prior_offset;
        *doubt = width;
        return s->gain_tn / s->gain_tt;
    }
    const double sum_n = s->gain_n - weight * mass_radius * prior_offset;
    const double fit = -(a11 * sum_n - a12 * s->gain_tn) / det / mass_radius;
    const double spread = width * sqrt(py_min(1.0, weight * a11 / det));
    if (fabs(fit) > tolerance) {
        *offset = copysign(tolerance, fit);
        *doubt = tolerance;
    } else {
        const double low = py_max(-tolerance, fit - spread), high = py_min(tolerance, fit + spread);
        *offset = 0.5 * (low + high);
        *doubt = 0.5 * (high - low);
    }
    return (s->gain_tn + mass_radius * *offset * s->gain_t) / s->gain_tt;
}

/* brake_gain.gain_within_offset_ambiguity: the middle of what the gain limits (1 ± limits) and
 * the body equation (gain ± ambiguity) both allow, its half-width into *doubt. */
static double gain_within_offset_ambiguity(double gain, double limits, double ambiguity, double *doubt)
{
    *doubt = 0.0;
    if (ambiguity <= 0.0)
        return gain;
    const double low = py_max(1.0 - limits, gain - ambiguity), high = py_min(1.0 + limits, gain + ambiguity);
    if (low > high)
        return gain;
    *doubt = 0.5 * (high - low);
    return 0.5 * (low + high);
}

/* body_equation._unexplained_torque, on the window sums of `s`. */
static double unexplained_torque(const FEState *s, double low, double high)
{
    const double mean_needed = s->recent_needed / s->recent_weight;
    const double mean_brake = s->recent_brake / s->recent_weight;
    const double lag_explains = s->recent_lag / s->recent_weight;
    if (mean_needed > high * mean_brake)
        return mean_needed - high * mean_brake - py_max(lag_explains, 0.0);
    if (mean_needed < low * mean_brake)
        return low * mean_brake - mean_needed - py_max(-lag_explains, 0.0);
    return 0.0;
}

/* body_equation.BodyEquation._learn_rolling_offset */
static void learn_rolling_offset(FEState *s, const double *k, double speed, const double *omega_dot, double a_raw,
                                 const double *drive)
{
    const double mass_radius = k[K_MASS] * k[K_RADIUS];
    const double torque = k[K_INERTIA] * sum_of(omega_dot, NW) - sum_of(drive, NW);
    const double resistance = k[K_ROLLING] * speed + k[K_DRAG] * speed * speed;
    const double offset = a_raw + resistance / k[K_MASS] + torque / mass_radius;
    if (!(isfinite(offset) && fabs(offset) <= SENSOR_OFFSET_LIMIT))
        return;
    const double air_doubt = resistance_doubt(k, speed, py_max(k[K_WIND_DOUBT], FAULT_WIND)) / k[K_MASS];
    s->rolling_samples += 1;
    const double alpha = py_max(py_min(1.0, k[K_SAMPLE_PERIOD] / py_max(k[K_BIAS_TAU], 1e-3)),
                                1.0 / (double)s->rolling_samples);
    const double before = s->rolling_offset;
    s->rolling_offset += alpha * (offset - before);
    s->rolling_m2 += (offset - before) * (offset - s->rolling_offset);
    s->rolling_air += alpha * (air_doubt - s->rolling_air);
    double prior_offset;
    const double prior_width = rolling_offset_prior(s, k, &prior_offset);
    gain_and_sensor_offset(s, SENSOR_OFFSET_PRIOR_S / k[K_SAMPLE_PERIOD], mass_radius, k[K_ACCEL_TOLERANCE],
                           prior_offset, prior_width, &s->sensor_offset, &s->sensor_offset_doubt);
}

/* FrontEnd._update_brake_gain */
static void update_brake_gain(FEState *s, const double *k, double accel_long, double speed, const double *inertia,
                              const double *brake, const double *drive, const double *wl, const double *rates,
                              int braking)
{
    const double decel = -accel_long;
    const double raw_brake = sum_of(brake, NW), raw_rate = sum_of(rates, NW);
    const double total_brake = py_max(raw_brake + s->lag[LAG_LAG] * raw_rate, 0.0);
    const double brake_rate = (total_brake - s->last_brake) / k[K_SAMPLE_PERIOD];
    s->last_brake = total_brake;
    s->unjudged += k[K_SAMPLE_PERIOD];
    if (s->unjudged > BRAKE_MODEL_WINDOW) {
        s->model_holds = 1;
        s->recent_weight = s->recent_needed = s->recent_brake = s->recent_lag = 0.0;
    }
    if (!braking || decel < k[K_GAIN_MIN_DECEL] || total_brake < 1.0 || !isfinite(brake_rate))
        return;
    const double locked = py_max(0.3, LOCKED_WHEEL_RATIO * speed);
    double slowest = wl[0];
    for (int i = 1; i < NW; i++)
        slowest = py_min(slowest, wl[i]);
    if (speed < k[K_MIN_SPEED] || slowest < locked)
        return;
    const double drag = k[K_ROLLING] * speed + k[K_DRAG] * speed * speed;
    const double total_force = k[K_MASS] * decel - drag;
    const double other = sum_of(inertia, NW) - sum_of(drive, NW);
    const double lim = k[K_GAIN_LIMITS];
    const double needed = total_force * k[K_RADIUS] - other;
    const double ratio = needed / total_brake;
    if (!isfinite(ratio))
        return;
    const double recent = 1.0 - py_min(1.0, k[K_SAMPLE_PERIOD] / BRAKE_MODEL_WINDOW);
    s->unjudged = 0.0;
    s->recent_weight = recent * s->recent_weight + total_brake;
    s->recent_needed = recent * s->recent_needed + total_brake * needed;
    s->recent_brake = recent * s->recent_brake + total_brake * total_brake;
    s->recent_lag = recent * s->recent_lag + total_brake * PRESSURE_SENSOR_LAG * brake_rate;
    const double window_ratio = s->recent_needed / s->recent_brake;
    const double gains = k[K_BRAKE_GAIN_FL] + k[K_BRAKE_GAIN_FR] + k[K_BRAKE_GAIN_RL] + k[K_BRAKE_GAIN_RR];
    const double accel_tolerance = BODY_ACCEL_TOLERANCE + s->sensor_offset_doubt;
    const double tolerance = k[K_MASS] * k[K_RADIUS] * accel_tolerance + PRESSURE_TOLERANCE * gains;
    const int resolved = unexplained_torque(s, 1.0, 1.0) > tolerance;
    const double wind = k[K_DRAG] * FAULT_WIND * (2.0 * speed + FAULT_WIND) * k[K_RADIUS];
    const int beyond_gains = unexplained_torque(s, (1.0 - lim) / BRAKE_MODEL_MARGIN,
                                                (1.0 + lim) * BRAKE_MODEL_MARGIN) > tolerance + wind;
    const int released = (k[K_MASTER_ONLY] != 0.0
                          && ((window_ratio < 1.0 - lim && resolved)
                              || (ratio < 1.0 - lim && total_brake - needed > tolerance)))
                         || s->released;
    s->released = released;
    s->model_holds = released || !beyond_gains;
    if (!released) {
        if (k[K_LAG_COMPENSATION] != 0.0)
            learn_pressure_lag(s, k, raw_brake, raw_rate, needed);
        /* (pressure_lag.PressureLag._needed_as_sensed: N through the sensors' learnt lag, fitted
         * against the pressures as read) */
        const double lag = s->lag[LAG_LAG], now = s->lag[LAG_TIME];
        const double elapsed = now - s->sensed_needed_time;
        double sensed = needed;
        if (lag > 0.0 && isfinite(s->sensed_needed) && 0.0 < elapsed && elapsed <= 1.5 * k[K_SAMPLE_PERIOD])
            sensed = s->sensed_needed + (needed - s->sensed_needed) * -expm1(-elapsed / lag);
        s->sensed_needed = sensed;
        s->sensed_needed_time = now;
        /* (brake_gain.BrakeGain._learn_brake_gain) */
        const int level = k[K_LEVEL_ROAD] != 0.0;
        const double mass_radius = k[K_MASS] * k[K_RADIUS], band = level ? 0.0 : mass_radius * SENSOR_OFFSET_LIMIT;
        const double keep = 1.0 - py_min(1.0, k[K_SAMPLE_PERIOD] / py_max(k[K_GAIN_TAU], 1e-3));
        const double fitted = level ? sensed : sensed - mass_radius * s->sensor_offset;
        const double n = py_min(py_max(fitted, (1.0 - lim) * raw_brake - band), (1.0 + lim) * raw_brake + band);
        s->gain_tt = keep * s->gain_tt + raw_brake * raw_brake;
        s->gain_tn = keep * s->gain_tn + raw_brake * n;
        double gain;
        if (level)
            gain = s->gain_tn / s->gain_tt;
        else {
            s->gain_t = keep * s->gain_t + raw_brake;
            s->gain_n = keep * s->gain_n + n;
            s->gain_w = keep * s->gain_w + 1.0;
            double prior_offset;
            const double prior_width = rolling_offset_prior(s, k, &prior_offset);
            gain = gain_and_sensor_offset(s, SENSOR_OFFSET_PRIOR_S / k[K_SAMPLE_PERIOD], mass_radius,
                                          k[K_ACCEL_TOLERANCE], prior_offset, prior_width, &s->sensor_offset,
                                          &s->sensor_offset_doubt);
        }
        /* (brake_gain.BrakeGain._unlearnt_offset_torque_nm) */
        const double doubt = s->sensor_offset_doubt;
        const double ambiguity = doubt > 0.0 && s->recent_brake > 0.0
            ? mass_radius * doubt / py_max(s->recent_brake / py_max(s->recent_weight, 1e-9), 1e-9)
            : 0.0;
        if (!level && !(1.0 - lim <= gain && gain <= 1.0 + lim)) {
            s->gain_factor = py_min(py_max(gain, 1.0 - lim), 1.0 + lim);
            s->gain_doubt = lim;
        } else
            s->gain_factor = gain_within_offset_ambiguity(gain, lim, ambiguity, &s->gain_doubt);
    }
}

/* An optional float of the inputs tuple: 1 and its value, 0 for None, -1 with an exception. */
static int input_at(PyObject *inputs, Py_ssize_t i, double *out)
{
    PyObject *v = PyTuple_GET_ITEM(inputs, i);
    if (v == Py_None)
        return 0;
    *out = PyFloat_AsDouble(v);
    return (*out == -1.0 && PyErr_Occurred()) ? -1 : 1;
}

static PyObject *make_result(PyObject *result_type, PyObject *sample, PyObject *stale, PyObject *fault,
                             PyObject *dead)
{
    PyObject *args[4] = {sample, stale, fault, dead};
    return PyObject_Vectorcall(result_type, args, dead ? 4 : 3, NULL);
}

/* sample_physics(fe, constants, types, t_c, omega, omega_dot, glitch, inputs, stale, matched_lookups,
 *                wheel_times, torque_weights, ref, ref_fresh, torque_omega_dot) -> FrontEndResult
 * types: (PhysicalSample, FrontEndResult, the six fault messages). */
static PyObject *py_sample_physics(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    PyObject *fe, *o_k, *types, *o_omega, *o_omega_dot, *inputs, *stale, *lookups, *o_times, *o_weights, *o_ref;
    double t_c, ref = 0.0;
    int glitch, ref_fresh;
    /* (METH_FASTCALL: converted here, once per trigger, without a format string) */
    if (!arg_count("sample_physics", nargs, 15))
        return NULL;
    fe = args[0], o_k = args[1], types = args[2], o_omega = args[4], o_omega_dot = args[5], inputs = args[7];
    stale = args[8], lookups = args[9], o_times = args[10], o_weights = args[11], o_ref = args[12];
    if (!arg_type(o_k, &PyTuple_Type, "constants") || !arg_type(types, &PyTuple_Type, "types")
        || !arg_double(args[3], &t_c) || !arg_bool(args[6], &glitch) || !arg_type(inputs, &PyTuple_Type, "inputs")
        || !arg_type(lookups, &PyTuple_Type, "matched_lookups") || !arg_bool(args[13], &ref_fresh))
        return NULL;
    if (PyTuple_GET_SIZE(o_k) != K_COUNT || PyTuple_GET_SIZE(types) != 8) {
        PyErr_SetString(PyExc_ValueError, "sample_physics: wrong number of constants or types");
        return NULL;
    }
    double k[K_COUNT];
    for (int i = 0; i < K_COUNT; i++)
        if ((k[i] = PyFloat_AsDouble(PyTuple_GET_ITEM(o_k, i))) == -1.0 && PyErr_Occurred())
            return NULL;
    PyObject *sample_type = PyTuple_GET_ITEM(types, 0), *result_type = PyTuple_GET_ITEM(types, 1);
    PyObject *f_accel = PyTuple_GET_ITEM(types, 2), *f_pressure = PyTuple_GET_ITEM(types, 3);
    PyObject *f_implausible = PyTuple_GET_ITEM(types, 4), *f_glitch = PyTuple_GET_ITEM(types, 5);
    PyObject *f_stuck = PyTuple_GET_ITEM(types, 6), *f_disagrees = PyTuple_GET_ITEM(types, 7);
    const int has_ref = o_ref != Py_None;
    if (has_ref && (ref = PyFloat_AsDouble(o_ref)) == -1.0 && PyErr_Occurred())
        return NULL;
    double omega[MAX_POINTS], omega_dot[MAX_POINTS], torque_omega_dot[MAX_POINTS];
    if (floats(o_omega, omega, "omega") != NW || floats(o_omega_dot, omega_dot, "omega_dot") != NW
        || (args[14] != Py_None && floats(args[14], torque_omega_dot, "torque_omega_dot") != NW)) {
        if (!PyErr_Occurred())
            PyErr_SetString(PyExc_ValueError, "sample_physics: four wheels");
        return NULL;
    }
    if (args[14] == Py_None)
        for (int i = 0; i < NW; i++)
            torque_omega_dot[i] = omega_dot[i];
    const int has_drive = k[K_HAS_DRIVE] != 0.0, has_yaw = k[K_HAS_YAW] != 0.0;
    const Py_ssize_t n_inputs = 6 + (has_drive ? NW : 0) + (has_yaw ? 1 : 0);
    if (PyTuple_GET_SIZE(inputs) != n_inputs) {
        PyErr_SetString(PyExc_ValueError, "sample_physics: inputs do not match the constants");
        return NULL;
    }
    /* The sample's inputs: accelerations and pressures required, drive torques and yaw rate optional. */
    double a_raw = 0.0, a_lat = 0.0, p[NW];
    int have = 1, got;
    if ((got = input_at(inputs, 0, &a_raw)) < 0)
        return NULL;
    have &= got;
    if ((got = input_at(inputs, 1, &a_lat)) < 0)
        return NULL;
    have &= got;
    for (int i = 0; i < NW; i++) {
        if ((got = input_at(inputs, 2 + i, &p[i])) < 0)
            return NULL;
        have &= got;
    }
    if (!have)
        return make_result(result_type, Py_None, stale, Py_None, NULL);
    if (fabs(a_raw) > MAX_ABS_ACCEL || fabs(a_lat) > MAX_ABS_ACCEL)
        return make_result(result_type, Py_None, stale, f_accel, NULL);
    for (int i = 0; i < NW; i++)
        if (!(-1.0 <= p[i] && p[i] <= MAX_PRESSURE))
            return make_result(result_type, Py_None, stale, f_pressure, NULL);
    double drive[NW] = {0.0, 0.0, 0.0, 0.0};
    if (has_drive)
        for (int i = 0; i < NW; i++) {
            double v;
            if ((got = input_at(inputs, 6 + i, &v)) < 0)
                return NULL;
            drive[i] = got && isfinite(v) ? v : 0.0;
        }

    FEState s;
    if (load_state(fe, &s) < 0)
        return NULL;
    const double radius = k[K_RADIUS];
    const double accel_long = a_raw - s.bias;   /* (what the car's speed does: free rolling's offset) */
    double wl[NW];
    int stuck[NW], braked[NW], dead[NW], failed[NW];
    int any_failed = 0, all_failed = 1, braking = 0, driving = 0, any_stuck = 0;
    for (int i = 0; i < NW; i++) {
        wl[i] = radius * omega[i];
        stuck[i] = fabs(accel_long) > 0.5 ? (double)s.repeats[i] >= k[K_STUCK_FRAMES] : 0;
        braked[i] = p[i] - k[K_PUSHOUT] > k[K_MIN_BRAKE_PRESSURE];
        braking |= braked[i];
        driving |= has_drive && fabs(drive[i]) > 20.0;
        any_stuck |= stuck[i];
    }
    if (!braking)
        s.released = 0;
    dead_wheels(&s, k, t_c, wl, braked, dead);
    for (int i = 0; i < NW; i++) {
        failed[i] = stuck[i] || dead[i];
        any_failed |= failed[i];
        all_failed &= failed[i];
    }
    if (any_failed && !all_failed) {
        /* The slowest working wheel stands in for a stuck or dead one. */
        double slowest_ok = 0.0;
        int first = 1;
        for (int i = 0; i < NW; i++)
            if (!failed[i]) {
                slowest_ok = first ? wl[i] : py_min(slowest_ok, wl[i]);
                first = 0;
            }
        for (int i = 0; i < NW; i++)
            if (failed[i])
                wl[i] = slowest_ok;
    }
    /* (wheels spinning back up after an ABS release explain the car's deceleration) */
    double spin_up = 0.0;
    for (int i = 0; i < NW; i++)
        if (omega_dot[i] > 0.0)
            spin_up += omega_dot[i];
    spin_up = k[K_INERTIA] * spin_up / (k[K_RADIUS] * k[K_MASS]);
    double fastest = wl[0], slowest = wl[0];
    for (int i = 1; i < NW; i++) {
        fastest = py_max(fastest, wl[i]);
        slowest = py_min(slowest, wl[i]);
    }
    /* (the contact forces' acceleration, less the air's drag up to its doubt: SensorFaults._deceleration_unexplained) */
    const double accel_contact = a_raw - s.sensor_offset;   /* (on a grade gravity shifts no load either) */
    const double air = (k[K_ROLLING] * fastest + k[K_DRAG] * fastest * fastest
                        + resistance_doubt(k, fastest, k[K_WIND_DOUBT])) / k[K_MASS];
    if (!braking && !driving && accel_contact + spin_up + air < -k[K_UNEXPLAINED_DECEL])
        s.unexplained += (s.has_last_sample && s.last_sample != 0.0) ? py_max(0.0, t_c - s.last_sample) : 0.0;
    else
        s.unexplained = 0.0;
    s.has_last_sample = 1;
    s.last_sample = t_c;
    if (s.unexplained > 0.1) {
        if (store_state(fe, &s) < 0)
            return NULL;
        return make_result(result_type, Py_None, stale, f_implausible, NULL);
    }
    int free_rolling = !braking && !driving && fastest - slowest <= FREE_ROLLING_SPREAD * fastest + 0.3;
    for (int i = 0; free_rolling && i < NW; i++)
        free_rolling = fabs(radius * omega_dot[i] - accel_long) < FREE_ROLLING_ACCEL;
    s.free_rolling = free_rolling;
    int from_ref;
    const double speed = update_speed(&s, k, t_c, wl, accel_long, !free_rolling, has_ref, ref, ref_fresh, &from_ref);
    if (free_rolling && t_c - s.slipping_time >= k[K_BIAS_SETTLE]) {
        /* FrontEnd._learn_accel_bias */
        const double wheel_accel = radius * (sum_of(omega_dot, NW) / NW);
        double alpha = py_min(1.0, k[K_SAMPLE_PERIOD] / py_max(k[K_BIAS_TAU], 1e-3));
        const double error = a_raw - wheel_accel;
        if (fabs(error) < 2.0) {
            s.bias_samples += 1;
            alpha = py_max(alpha, 1.0 / (double)s.bias_samples);
            const double before = s.bias;
            s.bias += alpha * (error - before);
            s.bias_m2 += (error - before) * (error - s.bias);
            if (k[K_LEVEL_ROAD] != 0.0) {
                s.sensor_offset = s.bias;
                s.sensor_offset_doubt = offset_doubt(s.bias_samples, s.bias_m2, k[K_ACCEL_TOLERANCE]);
            }
        }
        if (k[K_LEVEL_ROAD] == 0.0 && k[K_GAIN_CORRECTION] != 0.0 && k[K_COASTING_OFFSET] != 0.0)
            learn_rolling_offset(&s, k, speed, omega_dot, a_raw, drive);
    }
    double yaw_rate = 0.0;
    int have_yaw = 0;
    if (has_yaw && (have_yaw = input_at(inputs, n_inputs - 1, &yaw_rate)) < 0)
        return NULL;
    if (!have_yaw || !isfinite(yaw_rate))
        yaw_rate = speed > k[K_MIN_SPEED] ? a_lat / speed : 0.0;

    /* VehicleParams.normal_forces */
    const double h = k[K_CG_HEIGHT], wheelbase = k[K_CG_FRONT] + k[K_CG_REAR];
    const double front_axle = k[K_MASS] * (GRAVITY * k[K_CG_REAR] - h * accel_contact) / wheelbase;
    const double rear_axle = k[K_MASS] * (GRAVITY * k[K_CG_FRONT] + h * accel_contact) / wheelbase;
    const double lat_f = h * a_lat / (k[K_TRACK_FRONT] * GRAVITY), lat_r = h * a_lat / (k[K_TRACK_REAR] * GRAVITY);
    const double loads[NW] = {front_axle * (0.5 - lat_f), front_axle * (0.5 + lat_f), rear_axle * (0.5 - lat_r),
                              rear_axle * (0.5 + lat_r)};

    /* FrontEnd._matched_inputs */
    double torques[NW], accel_matched = a_raw;
    PyObject *matched = NULL;
    /* (and the brake torques' rates at the sample's instant where the pressure series give them) */
    double exact_rates[NW];
    int have_rate[NW] = {0, 0, 0, 0};
    if (o_weights != Py_None) {
        if (!PyTuple_Check(lookups)) {
            PyErr_SetString(PyExc_TypeError, "matched_many: the lookups are a tuple");
            return NULL;
        }
        double *times, *w;
        Py_ssize_t nt;
        if (window_of(o_times, o_weights, &times, &w, &nt) == 0)
            matched = matched_lookups(lookups, times, w, nt, NW, k + K_BRAKE_GAIN_FL, exact_rates, have_rate);
        PyMem_Free(times);
        PyMem_Free(w);
        if (!matched)
            return NULL;
        if (PyTuple_GET_SIZE(matched) != NW + 1) {
            Py_DECREF(matched);
            PyErr_SetString(PyExc_ValueError, "sample_physics: four pressures and an acceleration to match");
            return NULL;
        }
    }
    for (int i = 0; i <= NW; i++) {
        double m = 0.0;
        int have_m = 0;
        if (matched && (have_m = input_at(matched, i, &m)) < 0) {
            Py_DECREF(matched);
            return NULL;
        }
        if (i < NW)
            torques[i] = k[K_BRAKE_GAIN_FL + i] * (have_m ? m : py_max(0.0, p[i] - k[K_PUSHOUT]));
        else if (have_m)
            accel_matched = m;
    }
    Py_XDECREF(matched);
    double rates[NW], inertia[NW];
    brake_torque_rates(&s, k, t_c, torques, rates);
    for (int i = 0; i < NW; i++)
        if (have_rate[i])
            rates[i] = exact_rates[i];
    for (int i = 0; i < NW; i++)
        inertia[i] = k[K_INERTIA] * torque_omega_dot[i];
    if (k[K_GAIN_CORRECTION] != 0.0 && !glitch)
        update_brake_gain(&s, k, accel_matched - s.sensor_offset, speed, inertia, torques, drive, wl, rates, braking);
    const double gain = s.gain_factor;
    /* A sensor lagging by τ reads p(t) − τ·ṗ(t): the brakes' torque is the reading advanced by τ. */
    for (int i = 0; i < NW; i++)
        torques[i] = py_max(torques[i] + s.lag[LAG_LAG] * rates[i], 0.0);   /* (NaN stays NaN) */

    double slips[NW], forces[NW], mus[NW];
    PyObject *usable = PyTuple_New(NW), *sample = NULL, *dead_list = NULL, *result = NULL;
    if (!usable)
        return NULL;
    for (int i = 0; i < NW; i++) {
        const double side = (i % 2) ? 1.0 : -1.0, half_track = (i < 2 ? k[K_TRACK_FRONT] : k[K_TRACK_REAR]) / 2;
        const double ground = speed + side * yaw_rate * half_track;
        const double denom = py_max(ground, wl[i]);
        const double slip = denom > 0.1 ? (ground - wl[i]) / denom : 0.0;
        const double force = (inertia[i] + gain * torques[i] - drive[i]) / radius;
        const double load = loads[i];
        const double mu = load > 50.0 ? force / load : 0.0;
        if (braked[i] && slip > SETTLE_SLIP)
            s.slipping_time = t_c;
        /* FrontEnd._torqued_by_brakes */
        if (braked[i])
            s.braked_time[i] = t_c;
        const double since = t_c - s.braked_time[i];
        const int torqued = braked[i] || (0.0 <= since && since <= k[K_RELEASED_S] && slip >= k[K_RELEASED_MIN_SLIP]);
        const int ok = speed >= k[K_MIN_SPEED] && fabs(slip) <= k[K_MAX_SLIP]
                       && (torqued || (has_drive && fabs(drive[i]) > 20.0)) && load > 50.0 && !glitch && !stuck[i]
                       && !dead[i] && isfinite(mu) && s.model_holds && !s.released;
        slips[i] = slip;
        forces[i] = force;
        mus[i] = mu;
        PyTuple_SET_ITEM(usable, i, PyBool_FromLong(ok));
    }
    if (store_state(fe, &s) < 0)
        goto out;
    PyObject *t_slip = tuple_of(slips, NW), *t_mu = tuple_of(mus, NW), *t_load = tuple_of(loads, NW);
    PyObject *t_force = tuple_of(forces, NW), *o_tc = PyFloat_FromDouble(t_c), *o_speed = PyFloat_FromDouble(speed);
    if (t_slip && t_mu && t_load && t_force && o_tc && o_speed) {
        PyObject *fields[9] = {o_tc, o_speed, t_slip, t_mu, t_load, t_force, usable, braking ? Py_True : Py_False,
                               from_ref ? Py_True : Py_False};
        sample = PyObject_Vectorcall(sample_type, fields, 9, NULL);
    }
    Py_XDECREF(t_slip);
    Py_XDECREF(t_mu);
    Py_XDECREF(t_load);
    Py_XDECREF(t_force);
    Py_XDECREF(o_tc);
    Py_XDECREF(o_speed);
    if (!sample)
        goto out;
    int n_dead = 0;
    for (int i = 0; i < NW; i++)
        n_dead += dead[i];
    if (!(dead_list = PyTuple_New(n_dead)))
        goto out;
    for (int i = 0, j = 0; i < NW; i++)
        if (dead[i])
            PyTuple_SET_ITEM(dead_list, j++, PyLong_FromLong(i));
    PyObject *fault = glitch ? f_glitch : any_stuck ? f_stuck : (s.model_holds || !braking || speed < k[K_MIN_SPEED]) ? Py_None
                                                                                      : f_disagrees;
    result = make_result(result_type, sample, stale, fault, dead_list);
out:
    Py_XDECREF(usable);
    Py_XDECREF(sample);
    Py_XDECREF(dead_list);
    return result;
}

static int intern_attributes(void)
{
    struct { PyObject **slot; const char *name; } names[] = {
        {&A_repeats, "_repeats"}, {&A_dead, "_dead"}, {&A_low_since, "_low_since_s"},
        {&A_low_unbraked, "_low_unbraked_s"}, {&A_braked_time, "_braked_time_s"}, {&A_last_sample, "_last_sample_time_s"}, {&A_bias, "_accel_bias_mps2"},
        {&A_bias_samples, "_accel_bias_samples"}, {&A_bias_m2, "_accel_bias_m2"},
        {&A_rolling_offset, "_rolling_offset_mps2"}, {&A_rolling_samples, "_rolling_offset_samples"},
        {&A_rolling_m2, "_rolling_offset_m2"}, {&A_rolling_air, "_rolling_air_doubt_mps2"}, {&A_unexplained, "_unexplained_s"},
        {&A_speed_time, "_speed_time_s"}, {&A_speed_est, "_speed_estimate_mps"},
        {&A_ref_disagreements, "_ref_disagreements"}, {&A_gain_tt, "_gain_sum_tt"}, {&A_gain_tn, "_gain_sum_tn"},
        {&A_gain_t, "_gain_sum_t"}, {&A_gain_n, "_gain_sum_n"}, {&A_gain_w, "_gain_sum_w"},
        {&A_sensed_needed, "_sensed_needed_nm"}, {&A_sensed_needed_time, "_sensed_needed_time_s"},
        {&A_sensor_offset, "_sensor_offset_mps2"}, {&A_sensor_offset_doubt, "_sensor_offset_doubt_mps2"},
        {&A_recent_weight, "_recent_weight_nm"},
        {&A_recent_lag, "_recent_lag_nm"}, {&A_last_brake, "_last_brake_nm"}, {&A_recent_needed, "_recent_needed_nm"}, {&A_recent_brake, "_recent_brake_nm"},
        {&A_released, "_brake_released"}, {&A_gain_factor, "_brake_gain_factor"}, {&A_gain_doubt, "_brake_gain_doubt"},
        {&A_model_holds, "_brake_model_holds"}, {&A_unjudged, "_unjudged_s"}, {&A_lag_state, "_lag_state"},
        {&A_slipping_time, "_slipping_time_s"}, {&A_faster_since, "_wheels_faster_since_s"},
        {&A_restarted_braking, "_speed_restarted_braking"}, {&A_free_rolling, "_free_rolling_sample"},
    };
    for (size_t i = 0; i < sizeof names / sizeof names[0]; i++)
        if (!(*names[i].slot = PyUnicode_InternFromString(names[i].name)))
            return -1;
    return 0;
}


/* ---- the wheel-speed window's checks (wheel_speed_filter.WheelSpeedFilter) ----------------- */

/* newest_suspect(times, speeds, jerk) -> bool: WheelSpeedFilter._newest_suspect. `speeds`: one
 * 4-sequence per time. */
static PyObject *py_newest_suspect(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!arg_count("newest_suspect", nargs, 3))
        return NULL;
    double jerk;
    if (!arg_double(args[2], &jerk))
        return NULL;
    const Py_ssize_t n = PySequence_Size(args[0]);
    if (n < 0)
        return NULL;
    if (n < 4)
        Py_RETURN_FALSE;
    double t[4], y[4][4];
    for (int k = 0; k < 4; k++) {
        PyObject *item = PySequence_GetItem(args[0], n - 4 + k);
        const int ok = item && arg_double(item, &t[k]);
        Py_XDECREF(item);
        if (!ok)
            return NULL;
    }
    if (!(t[0] < t[1] && t[1] < t[2] && t[2] < t[3]))
        Py_RETURN_FALSE;
    for (int k = 0; k < 4; k++) {
        PyObject *row = PySequence_GetItem(args[1], n - 4 + k);
        const int ok = row && arg_doubles(row, y[k], 4, "speeds");
        Py_XDECREF(row);
        if (!ok)
            return NULL;
    }
    const double limit = jerk * ((t[3] - t[2]) * (t[3] - t[2]));
    for (int i = 0; i < 4; i++) {
        const double y0 = y[0][i], y1 = y[1][i], y2 = y[2][i], y3 = y[3][i];
        if (fabs(y3 - (y2 + (y2 - y1) * (t[3] - t[2]) / (t[2] - t[1]))) > limit)
            Py_RETURN_TRUE;
        const double trend = y1 + (y1 - y0) * (t[2] - t[1]) / (t[1] - t[0]);
        const double between = y1 + (y3 - y1) * (t[2] - t[1]) / (t[3] - t[1]);
        if (fabs(y2 - trend) > limit && fabs(y2 - between) > limit)
            Py_RETURN_TRUE;
    }
    Py_RETURN_FALSE;
}

/* slip_spread(weights, times, speeds, v, slips, accel) -> ((4 pairs), (a_lo, a_hi)) | None:
 * WheelSpeedFilter._attach_slip_spread's numbers (accel: the body's, offset taken off). */
static PyObject *py_slip_spread(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!arg_count("slip_spread", nargs, 6))
        return NULL;
    double v, accel, slip[4];
    if (!arg_double(args[3], &v) || !arg_doubles(args[4], slip, 4, "slips") || !arg_double(args[5], &accel))
        return NULL;
    Py_ssize_t n, n_weights;
    double *times = floats_of(args[1], &n, "times");
    if (!times)
        return NULL;
    double *weights = floats_of(args[0], &n_weights, "weights");
    if (!weights) {
        PyMem_Free(times);
        return NULL;
    }
    PyObject *result = NULL;
    if (n_weights < n) {
        PyErr_SetString(PyExc_ValueError, "slip_spread: a weight per time");
        goto out;
    }
    const Py_ssize_t centre = n / 2;
    const double t_c = n ? times[centre] : 0.0;
    Py_ssize_t lo = -1, hi = -1;
    double mean = 0.0, second = 0.0;
    for (Py_ssize_t k = 0; k < n; k++) {
        const double w = weights[k];
        if (w > 0.0) {
            if (lo < 0)
                lo = k;
            hi = k;
            const double d = times[k] - t_c;
            mean += w * d;
            second += w * d * d;
        }
    }
    if (!(0 <= lo && lo < centre && centre < hi)) {
        result = Py_NewRef(Py_None);
        goto out;
    }
    const double d_lo = times[lo] - t_c, d_hi = times[hi] - t_c;
    const double det = d_lo * d_hi * (d_hi - d_lo);
    if (!(det < 0.0)) {
        result = Py_NewRef(Py_None);
        goto out;
    }
    double a[2];
    a[0] = py_min(py_max((mean * d_hi * d_hi - second * d_hi) / det, 0.0), 0.5);
    a[1] = py_min(py_max((d_lo * second - d_lo * d_lo * mean) / det, 0.0), 0.5);
    const double ground_lo = 1.0 + accel * d_lo / v, ground_hi = 1.0 + accel * d_hi / v;
    double at[3][4];
    const Py_ssize_t rows[3] = {lo, centre, hi};
    for (int r = 0; r < 3; r++) {
        PyObject *row = PySequence_GetItem(args[2], rows[r]);
        const int ok = row && arg_doubles(row, at[r], 4, "speeds");
        Py_XDECREF(row);
        if (!ok)
            goto out;
    }
    double ends[8];
    for (int i = 0; i < 4; i++) {
        const double w_c = at[1][i];
        if (!(w_c > 0.5 && 0.0 <= slip[i] && slip[i] < 1.0)) {
            ends[2 * i] = ends[2 * i + 1] = slip[i];
            continue;
        }
        const double rolling = (1.0 - slip[i]) / w_c;
        ends[2 * i] = py_max(0.0, 1.0 - rolling * at[0][i] / ground_lo);
        ends[2 * i + 1] = py_max(0.0, 1.0 - rolling * at[2][i] / ground_hi);
    }
    PyObject *pairs = PyTuple_New(4);
    if (!pairs)
        goto out;
    for (int i = 0; i < 4; i++) {
        PyObject *pair = tuple_of(ends + 2 * i, 2);
        if (!pair) {
            Py_DECREF(pairs);
            goto out;
        }
        PyTuple_SET_ITEM(pairs, i, pair);
    }
    result = Py_BuildValue("(NN)", pairs, tuple_of(a, 2));
out:
    PyMem_Free(times);
    PyMem_Free(weights);
    return result;
}

/* ---- the tyre's relaxation (relaxation.RelaxationCompensator) ---------------------------- */

#define RELAX_COLUMNS 9

/* numpy.searchsorted(edges, x) (side "left"): a NaN sorts past every edge. */
static Py_ssize_t search_left(const double *edges, Py_ssize_t n, double x)
{
    if (x != x)
        return n;
    Py_ssize_t lo = 0, hi = n;
    while (lo < hi) {
        const Py_ssize_t mid = (lo + hi) / 2;
        if (edges[mid] < x)
            lo = mid + 1;
        else
            hi = mid;
    }
    return lo;
}

/* relaxation_step(sums, edges, memory_s, time_s, last_learnt_s, learn, lag, dt, speed, slips,
 *                 mu_before, mu, mu_after, usable_before, usable, usable_after, normal_forces,
 *                 tyre_forces)
 * -> (last_learnt_s, mus, forces): RelaxationCompensator._corrected's loop over the wheels and
 * its `_learn` (sums updated in place; last_learnt_s NaN for none yet). mus and forces are None
 * where no wheel was corrected. */
static PyObject *py_relaxation_step(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!arg_count("relaxation_step", nargs, 18))
        return NULL;
    double memory_s, time_s, last, lag, dt, speed;
    double slip[4], mu_b[4], mu_s[4], mu_a[4], fz[4], forces[4];
    int learn, use[4];
    if (!arg_double(args[2], &memory_s) || !arg_double(args[3], &time_s) || !arg_double(args[4], &last)
        || !arg_bool(args[5], &learn) || !arg_double(args[6], &lag) || !arg_double(args[7], &dt)
        || !arg_double(args[8], &speed) || !arg_doubles(args[9], slip, 4, "slips")
        || !arg_doubles(args[10], mu_b, 4, "mu_before") || !arg_doubles(args[11], mu_s, 4, "mu")
        || !arg_doubles(args[12], mu_a, 4, "mu_after") || !arg_doubles(args[16], fz, 4, "normal_forces")
        || !arg_doubles(args[17], forces, 4, "tyre_forces"))
        return NULL;
    for (int i = 0; i < 4; i++) {
        use[i] = 1;
        for (int k = 13; k <= 15; k++) {
            PyObject *item = PySequence_GetItem(args[k], i);
            if (!item)
                return NULL;
            const int truth = PyObject_IsTrue(item);
            Py_DECREF(item);
            if (truth < 0)
                return NULL;
            use[i] = use[i] && truth;
        }
    }
    Buf b[2];
    memset(b, 0, sizeof b);
    if (get_array(args[0], &b[0], "sums", -1, 1, 0) < 0 || get_array(args[1], &b[1], "edges", -1, 0, 0) < 0) {
        release_all(b, 2);
        return NULL;
    }
    double *sums = b[0].view.buf;
    const double *edges = b[1].view.buf;
    const Py_ssize_t n_edges = b[1].view.len / 8, n_sums = b[0].view.len / 8;
    if (n_sums != (n_edges + 1) * RELAX_COLUMNS) {
        release_all(b, 2);
        PyErr_SetString(PyExc_ValueError, "sums: expected (len(edges) + 1) rows of 9");
        return NULL;
    }
    double mus[4];
    int changed = 0;
    for (int i = 0; i < 4; i++) {
        mus[i] = mu_s[i];
        if (!use[i])
            continue;
        const double rate = (mu_a[i] - mu_b[i]) / dt;
        if (!isfinite(rate))
            continue;
        if (learn && isfinite(mu_s[i]) && isfinite(slip[i])) {
            if (last == last && time_s > last) {
                const double keep = exp(-(time_s - last) / memory_s);
                for (Py_ssize_t k = 0; k < n_sums; k++)
                    sums[k] *= keep;
            }
            last = time_s;
            const double z = rate / speed, l = slip[i], m = mu_s[i];
            double *row = sums + search_left(edges, n_edges, l) * RELAX_COLUMNS;
            const double add[RELAX_COLUMNS] = {1.0, l, l * l, z, z * z, z * l, m, m * l, m * z};
            for (int k = 0; k < RELAX_COLUMNS; k++)
                row[k] += add[k];
        }
        if (lag > 0.0) {
            mus[i] = mu_s[i] + lag * rate;
            forces[i] = mus[i] * fz[i];
            changed = 1;
        }
    }
    release_all(b, 2);
    PyObject *last_obj = PyFloat_FromDouble(last);
    if (!last_obj)
        return NULL;
    if (!changed)
        return Py_BuildValue("(NOO)", last_obj, Py_None, Py_None);
    return Py_BuildValue("(NNN)", last_obj, tuple_of(mus, 4), tuple_of(forces, 4));
}


/* numpy's sum of a float64 array, to the last bit: pairwise, eight accumulators within a block
 * (the arrays here are far shorter than numpy's 128-value block). */
static double numpy_sum(const double *a, Py_ssize_t n)
{
    if (n < 8) {
        double res = 0.0;
        for (Py_ssize_t i = 0; i < n; i++)
            res += a[i];
        return res;
    }
    if (n > 128) {
        const Py_ssize_t half = (n / 2) - (n / 2) % 8;
        return numpy_sum(a, half) + numpy_sum(a + half, n - half);
    }
    double r[8];
    for (int j = 0; j < 8; j++)
        r[j] = a[j];
    Py_ssize_t i;
    for (i = 8; i < n - (n % 8); i += 8)
        for (int j = 0; j < 8; j++)
            r[j] += a[i + j];
    double res = ((r[0] + r[1]) + (r[2] + r[3])) + ((r[4] + r[5]) + (r[6] + r[7]));
    for (; i < n; i++)
        res += a[i];
    return res;
}

/* relaxation_sigma(sums, min_band_samples, min_evidence_samples, max_sigma) -> float:
 * RelaxationCompensator._fitted_sigma. */
static PyObject *py_relaxation_sigma(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    (void)self;
    if (!arg_count("relaxation_sigma", nargs, 4))
        return NULL;
    double min_band, min_evidence, max_sigma;
    if (!arg_double(args[1], &min_band) || !arg_double(args[2], &min_evidence) || !arg_double(args[3], &max_sigma))
        return NULL;
    Buf b;
    memset(&b, 0, sizeof b);
    if (get_array(args[0], &b, "sums", -1, 0, 0) < 0) {
        release_all(&b, 1);
        return NULL;
    }
    const double *sums = b.view.buf;
    const Py_ssize_t rows = b.view.len / 8 / RELAX_COLUMNS;
    double count[64], var_z[64], cov_zm[64];
    Py_ssize_t k = 0;
    for (Py_ssize_t r = 0; r < rows && k < 64; r++) {
        const double *q = sums + r * RELAX_COLUMNS;
        if (!(q[0] >= min_band))
            continue;
        const double n = q[0], sl = q[1], sll = q[2], sz = q[3], szz = q[4], szl = q[5], sm = q[6], sml = q[7],
                     smz = q[8];
        const double var_l = sll - sl * sl / n, cov_zl = szl - sz * sl / n, cov_ml = sml - sm * sl / n;
        const double inv = var_l > 1e-12 ? 1.0 / var_l : 0.0;
        count[k] = n;
        var_z[k] = szz - sz * sz / n - cov_zl * cov_zl * inv;
        cov_zm[k] = smz - sz * sm / n - cov_zl * cov_ml * inv;
        k++;
    }
    release_all(&b, 1);
    if (rows > 64) {
        PyErr_SetString(PyExc_ValueError, "sums: at most 64 bands");
        return NULL;
    }
    if (k == 0)
        return PyFloat_FromDouble(0.0);
    const double den = numpy_sum(var_z, k);
    if (!(den > 0.0) || numpy_sum(count, k) < min_evidence)
        return PyFloat_FromDouble(0.0);
    const double sigma = -numpy_sum(cov_zm, k) / den;
    return PyFloat_FromDouble(isfinite(sigma) ? py_min(py_max(sigma, 0.0), max_sigma) : 0.0);
}

static PyMethodDef methods[] = {
    {"fit_wheels", py_fit_wheels, METH_VARARGS,
     "fit_wheels(times, speeds, spike_threshold, torque_window)\n"
     "-> (t_c, omega, omega_dot, glitch, torque_weights, torque_omega_dot) | None\n\n"
     "FrontEnd._fit_wheels' closed-form quadratic fit; None for degenerate timestamps."},
    {"matched", py_matched, METH_VARARGS,
     "matched(ts, vs, times, weights, floor) -> float: FrontEnd._matched's weighted sum of a series\n"
     "interpolated at the window's times (floor: None, or subtracted and clipped at 0 per value)."},
    {"matched_many", py_matched_many, METH_VARARGS,
     "matched_many(lookups, times, weights) -> tuple: `matched` of each (series dict, name, floor or None)\n"
     "of lookups (or None); None for a signal without a series yet."},
    {"push_values", (PyCFunction)(void (*)(void))py_push_values, METH_FASTCALL,
     "push_values(series, merged, time_s, values, new_pair) -> None: MessageHistory.push's loop\n"
     "(new_pair() makes the (times, values) deques of a signal seen for the first time)."},
    {"values_at", py_values_at, METH_VARARGS,
     "values_at(lookups, t) -> tuple: for each (series dict, name) of lookups (or None), what\n"
     "MessageHistory.value_at(t, name) gives: None when the signal has no series yet."},
    {"sample_physics", (PyCFunction)(void (*)(void))py_sample_physics, METH_FASTCALL,
     "sample_physics(fe, constants, types, t_c, omega, omega_dot, glitch, inputs, stale, matched_lookups,\n"
     "wheel_times, torque_weights, ref, ref_fresh, torque_omega_dot) -> FrontEndResult: FrontEnd._compute_sample after the\n"
     "fit and the inputs, reading and updating the FrontEnd's state attributes."},
    {"newest_suspect", (PyCFunction)(void (*)(void))py_newest_suspect, METH_FASTCALL,
     "newest_suspect(times, speeds, jerk) -> bool: WheelSpeedFilter._newest_suspect."},
    {"slip_spread", (PyCFunction)(void (*)(void))py_slip_spread, METH_FASTCALL,
     "slip_spread(weights, times, speeds, v, slips, accel) -> ((4 (lo, hi) pairs), (a_lo, a_hi)) | None:\n"
     "WheelSpeedFilter._attach_slip_spread's numbers (accel with the offset taken off)."},
    {"relaxation_step", (PyCFunction)(void (*)(void))py_relaxation_step, METH_FASTCALL,
     "relaxation_step(sums, edges, memory_s, time_s, last_learnt_s, learn, lag, dt, speed, slips, mu_before,\n"
     "mu, mu_after, usable_before, usable, usable_after, normal_forces, tyre_forces) -> (last_learnt_s, mus, forces):\n"
     "RelaxationCompensator._corrected's wheels (sums updated in place; mus, forces None if none corrected)."},
    {"relaxation_sigma", (PyCFunction)(void (*)(void))py_relaxation_sigma, METH_FASTCALL,
     "relaxation_sigma(sums, min_band_samples, min_evidence_samples, max_sigma) -> float:\n"
     "RelaxationCompensator._fitted_sigma."},
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
    if (!deque_append || intern_attributes() < 0)
        return NULL;
    return PyModule_Create(&module);
}
