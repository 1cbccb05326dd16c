/*
 * The codec's per-frame work, compiled: reading an input payload's mapped signals into SI units,
 * packing output values into a classical (≤ 8 byte) payload with shifts and masks, and the E2E
 * counter + CRC. Knows CAN payloads, nothing of tyres.
 *
 * Each function reproduces its Python twin in frictiond/codec.py (`InputCodec.decode`'s fast path,
 * `_Packer.encode`'s shift-and-mask path) and frictiond/e2e.py (`protect`) bit for bit;
 * tests/test_codeccore.py holds them to it.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#include <math.h>
#include <stdint.h>

/* One signal of a message, as codec._Packer.field_spec packs it ("<4d3qQ2q", 80 bytes). */
typedef struct {
    double lo, hi;        /* the physical range a value is clipped to (NaN → lo) */
    double scale, offset; /* raw = round((value - offset) / scale); identity: round(value) */
    int64_t identity;
    int64_t little;       /* 1: bits of the payload read little-endian, 0: big-endian */
    int64_t shift;
    uint64_t mask;
    int64_t low, high;    /* the raw values the field holds */
} Field;

/* A value as a double when it is a Python float or an int a double holds exactly; else -1. */
static int as_double(PyObject *v, double *out)
{
    if (PyFloat_Check(v)) {
        *out = PyFloat_AS_DOUBLE(v);
        return 0;
    }
    if (PyLong_Check(v)) {
        int overflow = 0;
        const long long i = PyLong_AsLongLongAndOverflow(v, &overflow);
        if (overflow || (i == -1 && PyErr_Occurred())) {
            PyErr_Clear();
            return -1;
        }
        if (i > (1LL << 53) || i < -(1LL << 53))
            return -1;
        *out = (double)i;
        return 0;
    }
    return -1;
}

/* _Packer.encode's shift-and-mask path into out[0..length): 1 done, 0 the Python path must
 * decide (a value that is not a plain number, a raw value outside its field), -1 an exception. */
static int pack_into(const Py_buffer *spec, PyObject *names, PyObject *values, Py_ssize_t length, unsigned char *out)
{
    const Py_ssize_t count = spec->len / (Py_ssize_t)sizeof(Field);
    if (spec->len % (Py_ssize_t)sizeof(Field) || count != PyTuple_GET_SIZE(names) || length < 0 || length > 8) {
        PyErr_SetString(PyExc_ValueError, "pack: spec, names and length (≤ 8) do not agree");
        return -1;
    }
    Field field;
    uint64_t big = 0, little = 0;
    for (Py_ssize_t k = 0; k < count; k++) {
        memcpy(&field, (const char *)spec->buf + k * (Py_ssize_t)sizeof(Field), sizeof(Field));
        PyObject *name = PyTuple_GET_ITEM(names, k);
        PyObject *item = PyDict_GetItemWithError(values, name);
        if (!item) {
            if (!PyErr_Occurred())
                PyErr_SetObject(PyExc_KeyError, name);
            return -1;
        }
        double value;
        if (as_double(item, &value) < 0)
            return 0;
        if (value != value)
            value = field.lo;
        else {
            if (field.lo > value)
                value = field.lo;
            if (field.hi < value)
                value = field.hi;
        }
        /* nearbyint rounds half to even in the default mode, as Python's round() */
        const double raw = field.identity ? nearbyint(value) : nearbyint((value - field.offset) / field.scale);
        if (!(raw >= (double)field.low && raw <= (double)field.high))
            return 0;
        const uint64_t bits = ((uint64_t)(int64_t)raw & field.mask) << field.shift;
        if (field.little)
            little |= bits;
        else
            big |= bits;
    }
    for (Py_ssize_t i = 0; i < length; i++)
        out[i] = (unsigned char)(((little >> (8 * i)) | (big >> (8 * (length - 1 - i)))) & 0xFF);
    return 1;
}

static unsigned char crc_table[256];

static void make_crc_table(void)
{
    for (int byte = 0; byte < 256; byte++) {
        unsigned crc = (unsigned)byte;
        for (int bit = 0; bit < 8; bit++)
            crc = crc & 0x80 ? ((crc << 1) ^ 0x1D) & 0xFF : (crc << 1) & 0xFF;
        crc_table[byte] = (unsigned char)crc;
    }
}

/* e2e.protect on out[0..n): 0, or -1 with an exception. */
static int protect_in_place(unsigned char *out, Py_ssize_t n, long long data_id, long long counter, long long counter_bit)
{
    const long long byte = counter_bit >= 0 ? counter_bit / 8 : -1;
    if (n < 1 || byte < 0 || byte >= n) {
        PyErr_SetString(PyExc_IndexError, "protect: counter or CRC byte outside the payload");
        return -1;
    }
    if (counter_bit % 8 > 4) {
        PyErr_SetString(PyExc_ValueError, "protect: the 4-bit counter would cross a byte boundary");
        return -1;
    }
    const int shift = (int)(counter_bit % 8);
    out[byte] = (unsigned char)((out[byte] & ~(0x0F << shift) & 0xFF) | ((counter & 0x0F) << shift));
    unsigned crc = crc_table[0xFF ^ (data_id & 0xFF)];
    crc = crc_table[crc ^ ((data_id >> 8) & 0xFF)];
    for (Py_ssize_t i = 1; i < n && i < 8; i++)
        crc = crc_table[crc ^ out[i]];
    out[0] = (unsigned char)(crc ^ 0xFF);
    return 0;
}

static PyObject *py_protect(PyObject *self, PyObject *args)
{
    Py_buffer payload;
    long long data_id, counter, counter_bit;
    if (!PyArg_ParseTuple(args, "Ly*LL", &data_id, &payload, &counter, &counter_bit))
        return NULL;
    const Py_ssize_t n = payload.len;
    unsigned char out[64];
    if (n > 64) {
        PyBuffer_Release(&payload);
        PyErr_SetString(PyExc_ValueError, "protect: a payload of at most 64 bytes");
        return NULL;
    }
    memcpy(out, payload.buf, (size_t)n);
    PyBuffer_Release(&payload);
    if (protect_in_place(out, n, data_id, counter, counter_bit) < 0)
        return NULL;
    return PyBytes_FromStringAndSize((const char *)out, n);
}

/* pack_into's payload as bytes, protected first when e2e (data ID, counter, counter bit) is given;
 * None as pack_into's 0. Releases the spec. */
static PyObject *packed(Py_buffer *spec, PyObject *names, PyObject *values, Py_ssize_t length, const long long *e2e)
{
    unsigned char out[8];
    const int done = pack_into(spec, names, values, length, out);
    PyBuffer_Release(spec);
    if (done < 0)
        return NULL;
    if (!done)
        Py_RETURN_NONE;
    if (e2e && protect_in_place(out, length, e2e[0], e2e[1], e2e[2]) < 0)
        return NULL;
    return PyBytes_FromStringAndSize((const char *)out, length);
}

static PyObject *py_pack(PyObject *self, PyObject *args)
{
    Py_buffer spec;
    PyObject *names, *values;
    Py_ssize_t length;
    if (!PyArg_ParseTuple(args, "y*O!O!n", &spec, &PyTuple_Type, &names, &PyDict_Type, &values, &length))
        return NULL;
    return packed(&spec, names, values, length, NULL);
}

static PyObject *py_encode_frame(PyObject *self, PyObject *args)
{
    Py_buffer spec;
    PyObject *names, *values;
    Py_ssize_t length;
    long long e2e[3];   /* data ID, counter, counter bit */
    if (!PyArg_ParseTuple(args, "y*O!O!nLLL", &spec, &PyTuple_Type, &names, &PyDict_Type, &values, &length,
                          &e2e[0], &e2e[1], &e2e[2]))
        return NULL;
    return packed(&spec, names, values, length, e2e);
}

/* One signal read from an input payload, as codec._MessagePlan.compiled_spec packs it ("<2qQ2q2d"). */
typedef struct {
    int64_t little, shift;
    uint64_t mask;
    int64_t sign;         /* the sign bit's value for a signed field, else 0 */
    int64_t identity;
    double scale, offset; /* cantools' value = raw * scale + offset (identity: raw) */
} InField;

typedef struct {          /* a DBC range check ("<q2d") */
    int64_t field;
    double low, high;
} InCheck;

typedef struct {          /* a canonical value = (value * scale + offset) * factor ("<q3d") */
    int64_t field;
    double scale, offset, factor;
} InSI;

#define MAX_IN_FIELDS 64

/* METH_FASTCALL, arguments converted here: four times per wheel-speed frame, where the
 * format-string parsing of PyArg_ParseTuple cost as much as the unpacking. */
static PyObject *py_unpack_si(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    Py_buffer fields, checks, si, data;
    PyObject *names;
    Py_ssize_t counter;
    if (nargs != 6) {
        PyErr_Format(PyExc_TypeError, "unpack_si() takes 6 arguments (%zd given)", nargs);
        return NULL;
    }
    if (!PyTuple_Check(args[3])) {
        PyErr_SetString(PyExc_TypeError, "unpack_si() argument 4 must be tuple");
        return NULL;
    }
    names = args[3];
    counter = PyNumber_AsSsize_t(args[4], PyExc_OverflowError);
    if (counter == -1 && PyErr_Occurred())
        return NULL;
    if (PyObject_GetBuffer(args[0], &fields, PyBUF_SIMPLE) < 0)
        return NULL;
    if (PyObject_GetBuffer(args[1], &checks, PyBUF_SIMPLE) < 0) {
        PyBuffer_Release(&fields);
        return NULL;
    }
    if (PyObject_GetBuffer(args[2], &si, PyBUF_SIMPLE) < 0) {
        PyBuffer_Release(&fields);
        PyBuffer_Release(&checks);
        return NULL;
    }
    if (PyObject_GetBuffer(args[5], &data, PyBUF_SIMPLE) < 0) {
        PyBuffer_Release(&fields);
        PyBuffer_Release(&checks);
        PyBuffer_Release(&si);
        return NULL;
    }
    PyObject *result = NULL, *values = NULL;
    const Py_ssize_t nf = fields.len / (Py_ssize_t)sizeof(InField), nc = checks.len / (Py_ssize_t)sizeof(InCheck),
                     ns = si.len / (Py_ssize_t)sizeof(InSI);
    if (fields.len % (Py_ssize_t)sizeof(InField) || checks.len % (Py_ssize_t)sizeof(InCheck)
        || si.len % (Py_ssize_t)sizeof(InSI) || ns != PyTuple_GET_SIZE(names) || nf > MAX_IN_FIELDS
        || counter >= nf || data.len > 8) {
        PyErr_SetString(PyExc_ValueError, "unpack_si: the tables, names and payload (≤ 8 bytes) do not agree");
        goto done;
    }
    uint64_t little = 0, big = 0;
    const unsigned char *bytes = data.buf;
    for (Py_ssize_t i = 0; i < data.len; i++) {
        little |= (uint64_t)bytes[i] << (8 * i);
        big |= (uint64_t)bytes[i] << (8 * (data.len - 1 - i));
    }
    double value[MAX_IN_FIELDS];
    int64_t raw_of[MAX_IN_FIELDS];
    for (Py_ssize_t k = 0; k < nf; k++) {
        InField f;
        memcpy(&f, (const char *)fields.buf + k * (Py_ssize_t)sizeof(InField), sizeof f);
        int64_t raw = (int64_t)(((f.little ? little : big) >> f.shift) & f.mask);
        if (f.sign && (raw & f.sign))
            raw -= f.sign << 1;
        raw_of[k] = raw;
        value[k] = f.identity ? (double)raw : (double)raw * f.scale + f.offset;
    }
    for (Py_ssize_t k = 0; k < nc; k++) {
        InCheck c;
        memcpy(&c, (const char *)checks.buf + k * (Py_ssize_t)sizeof(InCheck), sizeof c);
        if (c.field < 0 || c.field >= nf || !(c.low <= value[c.field] && value[c.field] <= c.high)) {
            result = Py_NewRef(Py_None);   /* refused: the Python path says why */
            goto done;
        }
    }
    values = PyDict_New();
    if (!values)
        goto done;
    for (Py_ssize_t k = 0; k < ns; k++) {
        InSI m;
        memcpy(&m, (const char *)si.buf + k * (Py_ssize_t)sizeof(InSI), sizeof m);
        if (m.field < 0 || m.field >= nf) {
            PyErr_SetString(PyExc_ValueError, "unpack_si: a canonical value names no field");
            goto done;
        }
        const double v = (value[m.field] * m.scale + m.offset) * m.factor;
        if (!isfinite(v)) {
            result = Py_NewRef(Py_None);
            goto done;
        }
        PyObject *number = PyFloat_FromDouble(v);
        if (!number || PyDict_SetItem(values, PyTuple_GET_ITEM(names, k), number) < 0) {
            Py_XDECREF(number);
            goto done;
        }
        Py_DECREF(number);
    }
    PyObject *counter_value;
    if (counter < 0) {
        counter_value = Py_NewRef(Py_None);
    } else {
        InField f;
        memcpy(&f, (const char *)fields.buf + counter * (Py_ssize_t)sizeof(InField), sizeof f);
        counter_value = f.identity ? PyLong_FromLongLong(raw_of[counter]) : PyFloat_FromDouble(value[counter]);
        if (!counter_value)
            goto done;
    }
    result = Py_BuildValue("(ON)", values, counter_value);
done:
    Py_XDECREF(values);
    PyBuffer_Release(&fields);
    PyBuffer_Release(&checks);
    PyBuffer_Release(&si);
    PyBuffer_Release(&data);
    return result;
}

/* The FRICTION_WHEEL signals encode_wheels sets, interned at import. */
static PyObject *K_crc, *K_counter, *K_wheel_index, *K_slip, *K_mu_used, *K_mu_max_wheel, *K_normal_force;

/* encode_wheels(specs, length, data_id, counter, counter_bit, slips, mus_used, mus_max, loads, extra)
 * -> [4 payloads] | None: OutputCodec.encode_wheels' four frames, wheel i with counter + i, each
 * as encode_frame (its values: the wheel's numbers, a non-finite one as 0.0, and `extra`). None
 * when a spec is missing or a frame is refused (the caller then takes the Python path). */
static PyObject *py_encode_wheels(PyObject *self, PyObject *const *args, Py_ssize_t nargs)
{
    PyObject *specs, *quads[4], *extra;
    Py_ssize_t length;
    long long data_id, counter, counter_bit;
    /* (METH_FASTCALL: converted here, once per update, without a format string) */
    if (nargs != 10) {
        PyErr_Format(PyExc_TypeError, "encode_wheels() takes 10 arguments (%zd given)", nargs);
        return NULL;
    }
    specs = args[0], extra = args[9];
    for (int i = 0; i < 4; i++)
        quads[i] = args[5 + i];
    if (!PyTuple_Check(specs) || !PyDict_Check(extra)) {
        PyErr_SetString(PyExc_TypeError, "encode_wheels: specs must be a tuple, extra a dict");
        return NULL;
    }
    length = PyNumber_AsSsize_t(args[1], PyExc_OverflowError);
    if (length == -1 && PyErr_Occurred())
        return NULL;
    long long *const integers[3] = {&data_id, &counter, &counter_bit};
    for (int i = 0; i < 3; i++) {
        PyObject *number = PyNumber_Index(args[2 + i]);
        if (!number)
            return NULL;
        *integers[i] = PyLong_AsLongLong(number);
        Py_DECREF(number);
        if (*integers[i] == -1 && PyErr_Occurred())
            return NULL;
    }
    if (PyTuple_GET_SIZE(specs) != 4) {
        PyErr_SetString(PyExc_ValueError, "encode_wheels: one spec per wheel");
        return NULL;
    }
    PyObject *const keys[4] = {K_slip, K_mu_used, K_mu_max_wheel, K_normal_force};
    PyObject *payloads = PyList_New(4);
    if (!payloads)
        return NULL;
    for (Py_ssize_t i = 0; i < 4; i++) {
        PyObject *spec = PyTuple_GET_ITEM(specs, i);
        if (!PyTuple_Check(spec) || PyTuple_GET_SIZE(spec) != 2 || !PyTuple_Check(PyTuple_GET_ITEM(spec, 1))) {
            Py_DECREF(payloads);
            Py_RETURN_NONE;
        }
        PyObject *values = PyDict_Copy(extra), *index = PyLong_FromSsize_t(i), *zero = PyLong_FromLong(0);
        int failed = !values || !index || !zero || PyDict_SetItem(values, K_crc, zero) < 0
                     || PyDict_SetItem(values, K_counter, zero) < 0 || PyDict_SetItem(values, K_wheel_index, index) < 0;
        for (int q = 0; q < 4 && !failed; q++) {
            PyObject *item = PySequence_GetItem(quads[q], i);
            const double v = item ? PyFloat_AsDouble(item) : -1.0;
            Py_XDECREF(item);
            PyObject *number = (v == -1.0 && PyErr_Occurred()) ? NULL : PyFloat_FromDouble(isfinite(v) ? v : 0.0);
            failed = !number || PyDict_SetItem(values, keys[q], number) < 0;
            Py_XDECREF(number);
        }
        Py_XDECREF(index);
        Py_XDECREF(zero);
        Py_buffer view;
        if (failed || PyObject_GetBuffer(PyTuple_GET_ITEM(spec, 0), &view, PyBUF_SIMPLE) < 0) {
            Py_XDECREF(values);
            Py_DECREF(payloads);
            return NULL;
        }
        const long long e2e[3] = {data_id, (counter + i) & 0x0F, counter_bit};
        PyObject *payload = packed(&view, PyTuple_GET_ITEM(spec, 1), values, length, e2e);
        Py_DECREF(values);
        if (!payload || payload == Py_None) {
            Py_DECREF(payloads);
            return payload;
        }
        PyList_SET_ITEM(payloads, i, payload);
    }
    return payloads;
}

static PyMethodDef methods[] = {
    {"unpack_si", (PyCFunction)(void (*)(void))py_unpack_si, METH_FASTCALL,
     "unpack_si(fields, checks, si, names, counter, data) -> (values, counter value) | None\n\n"
     "InputCodec.decode's fast path for a classical payload: the mapped signals in SI units by\n"
     "canonical name and the alive counter's value (None without one); None when a DBC range\n"
     "check fails or a value is not finite (the Python path then raises the DecodeFailure)."},
    {"pack", py_pack, METH_VARARGS,
     "pack(spec, names, values, length) -> bytes | None\n\n"
     "codec._Packer.encode's shift-and-mask path for a message of ≤ 8 bytes; None when a value is\n"
     "not a plain number or its raw value does not fit its field (the Python path handles those).\n"
     "With protect, the two steps of encode_frame, each held to its Python twin by the tests."},
    {"encode_frame", py_encode_frame, METH_VARARGS,
     "encode_frame(spec, names, values, length, data_id, counter, counter_bit) -> bytes | None:\n"
     "pack, then protect; None as pack."},
    {"encode_wheels", (PyCFunction)(void (*)(void))py_encode_wheels, METH_FASTCALL,
     "encode_wheels(specs, length, data_id, counter, counter_bit, slips, mus_used, mus_max, loads, extra)\n"
     "-> [4 payloads] | None: the four FRICTION_WHEEL frames, wheel i with counter + i (encode_frame each)."},
    {"protect", py_protect, METH_VARARGS,
     "protect(data_id, payload, counter, counter_bit) -> bytes: e2e.protect on a copy."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_codeccore",
                                    "The output codec's per-frame packing and E2E protection, compiled.",
                                    -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__codeccore(void)
{
    make_crc_table();
    if (!(K_crc = PyUnicode_InternFromString("Crc")) || !(K_counter = PyUnicode_InternFromString("Counter"))
        || !(K_wheel_index = PyUnicode_InternFromString("WheelIndex")) || !(K_slip = PyUnicode_InternFromString("Slip"))
        || !(K_mu_used = PyUnicode_InternFromString("MuUsed"))
        || !(K_mu_max_wheel = PyUnicode_InternFromString("MuMaxWheel"))
        || !(K_normal_force = PyUnicode_InternFromString("NormalForce")))
        return NULL;
    return PyModule_Create(&module);
}
