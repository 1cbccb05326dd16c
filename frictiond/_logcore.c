/*
 * Reading candump -L log lines, compiled: the common line (a classical data frame) straight into a
 * frictiond Frame. Reproduces busio._read_candump's regular-expression path exactly; any other
 * line (CAN FD, remote and error frames, odd spacing) returns None and takes the Python path,
 * which follows python-can's reader. tests/test_logcore.py holds the two to the same frames.
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>

static int hex_value(char c)
{
    if (c >= '0' && c <= '9')
        return c - '0';
    if (c >= 'a' && c <= 'f')
        return c - 'a' + 10;
    if (c >= 'A' && c <= 'F')
        return c - 'A' + 10;
    return -1;
}

static int is_digit(char c)
{
    return c >= '0' && c <= '9';
}

#define MAX_TIME_CHARS 63

/* Where the parts of a common line lie (offsets into the line). */
typedef struct {
    Py_ssize_t time_start, time_len, data_start, data_len, id_len;
    unsigned long can_id;
} CandumpLine;

/* `(time) channel ID#HEX[ R|T]\n?` as _CANDUMP_DATA_LINE matches it, and a classical data frame
   (no error flag, whole bytes): 1 with its parts in *out; 0 for any other line. */
static int parse_line(const char *s, Py_ssize_t n, CandumpLine *out)
{
    Py_ssize_t i = 0;
    if (i >= n || s[i] != '(')
        return 0;
    const Py_ssize_t time_start = ++i;
    if (i < n && s[i] == '-')
        i++;
    const Py_ssize_t int_start = i;
    while (i < n && is_digit(s[i]))
        i++;
    if (i == int_start || i >= n || s[i] != '.')
        return 0;
    const Py_ssize_t frac_start = ++i;
    while (i < n && is_digit(s[i]))
        i++;
    if (i == frac_start || i + 1 >= n || s[i] != ')' || s[i + 1] != ' ')
        return 0;
    out->time_start = time_start;
    out->time_len = i - time_start;
    i += 2;
    const Py_ssize_t channel_start = i;   /* [!-~]+ then one space */
    while (i < n && s[i] >= '!' && s[i] <= '~')
        i++;
    if (i == channel_start || i >= n || s[i] != ' ')
        return 0;
    const Py_ssize_t id_start = ++i;
    unsigned long can_id = 0;
    while (i < n && hex_value(s[i]) >= 0 && i - id_start < 8)
        can_id = (can_id << 4) | (unsigned long)hex_value(s[i++]);
    out->id_len = i - id_start;
    if (out->id_len == 0 || i >= n || s[i] != '#')
        return 0;
    out->data_start = ++i;
    while (i < n && hex_value(s[i]) >= 0)
        i++;
    out->data_len = i - out->data_start;
    if (i + 1 < n && s[i] == ' ' && (s[i + 1] == 'R' || s[i + 1] == 'r' || s[i + 1] == 'T' || s[i + 1] == 't'))
        i += 2;
    if (i < n && s[i] == '\n')
        i++;
    if (i != n || (can_id & 0x20000000UL) || (out->data_len & 1))
        return 0;   /* trailing text, an error frame, half a byte: the Python path */
    out->can_id = can_id;
    return 1;
}

/* float() of the line's time text: the same conversion Python's float() does. -1.0 with an
   exception set on failure. */
static double line_time(const char *s, const CandumpLine *line)
{
    char short_text[MAX_TIME_CHARS + 1];
    char *time_text = short_text;
    if (line->time_len > MAX_TIME_CHARS) {   /* a long fraction: rare, but python-can takes it */
        time_text = PyMem_Malloc((size_t)line->time_len + 1);
        if (!time_text) {
            PyErr_NoMemory();
            return -1.0;
        }
    }
    memcpy(time_text, s + line->time_start, (size_t)line->time_len);
    time_text[line->time_len] = '\0';
    const double time_s = PyOS_string_to_double(time_text, NULL, NULL);
    if (time_text != short_text)
        PyMem_Free(time_text);
    return time_s;
}

/* Frame(time, id, data, extended, False, False) without Frame's Python-level __new__. */
static PyObject *new_frame(PyTypeObject *frame_type, const char *s, const CandumpLine *line)
{
    const double time_s = line_time(s, line);
    if (time_s == -1.0 && PyErr_Occurred())
        return NULL;
    const Py_ssize_t size = line->data_len / 2;
    PyObject *payload = PyBytes_FromStringAndSize(NULL, size);
    if (!payload)
        return NULL;
    char *bytes = PyBytes_AS_STRING(payload);
    const char *hex = s + line->data_start;
    for (Py_ssize_t k = 0; k < size; k++)
        bytes[k] = (char)(hex_value(hex[2 * k]) << 4 | hex_value(hex[2 * k + 1]));
    PyObject *time_obj = PyFloat_FromDouble(time_s);
    PyObject *id_obj = PyLong_FromUnsignedLong(line->can_id & 0x1FFFFFFFUL);
    /* what tuple.__new__(Frame, items) does: the subtype's own allocation, then the items */
    PyObject *frame = frame_type->tp_alloc(frame_type, 6);
    if (!time_obj || !id_obj || !frame) {
        Py_XDECREF(time_obj);
        Py_XDECREF(id_obj);
        Py_XDECREF(frame);
        Py_DECREF(payload);
        return NULL;
    }
    PyObject *extended = line->id_len > 3 ? Py_True : Py_False;
    Py_INCREF(extended);
    Py_INCREF(Py_False);
    Py_INCREF(Py_False);
    PyTuple_SET_ITEM(frame, 0, time_obj);
    PyTuple_SET_ITEM(frame, 1, id_obj);
    PyTuple_SET_ITEM(frame, 2, payload);
    PyTuple_SET_ITEM(frame, 3, extended);
    PyTuple_SET_ITEM(frame, 4, Py_False);
    PyTuple_SET_ITEM(frame, 5, Py_False);
    /* Only floats, ints, bytes and bools inside: no cycle can pass through it, so the collector
       need not visit it (CPython untracks such tuples itself, but only once a collection has
       looked at them: a block of 25 000 frames paid ~35 collections for that). */
    if (frame_type->tp_dictoffset == 0)
        PyObject_GC_UnTrack(frame);
    return frame;
}

static int is_frame_type(PyObject *frame_type)
{
    if (PyType_Check(frame_type) && PyType_IsSubtype((PyTypeObject *)frame_type, &PyTuple_Type))
        return 1;
    PyErr_SetString(PyExc_TypeError, "frame_type must be a tuple subclass (frames.Frame)");
    return 0;
}

static PyObject *py_candump_frame(PyObject *self, PyObject *args)
{
    PyObject *text, *frame_type;
    if (!PyArg_ParseTuple(args, "UO", &text, &frame_type) || !is_frame_type(frame_type))
        return NULL;
    CandumpLine line;
    if (!PyUnicode_IS_ASCII(text) ||
        !parse_line((const char *)PyUnicode_DATA(text), PyUnicode_GET_LENGTH(text), &line))
        Py_RETURN_NONE;
    return new_frame((PyTypeObject *)frame_type, (const char *)PyUnicode_DATA(text), &line);
}

/* Nothing but whitespace as str.strip() sees it: a line the reader passes over. */
static int is_blank(const char *s, Py_ssize_t n)
{
    for (Py_ssize_t i = 0; i < n; i++)
        if (!Py_UNICODE_ISSPACE((Py_UCS4)(unsigned char)s[i]))
            return 0;
    return 1;
}

#define STANDARD_ID_BITMAP_BYTES 512   /* one bit per ID of up to three hex digits */

/* candump_lines(text, frame_type, keep) -> (items, slow_lines, skipped, lead_time, tail_time) | None */
static PyObject *py_candump_lines(PyObject *self, PyObject *args)
{
    PyObject *text, *frame_type, *keep;
    if (!PyArg_ParseTuple(args, "UOO", &text, &frame_type, &keep) || !is_frame_type(frame_type))
        return NULL;
    const unsigned char *keep_bits = NULL;
    if (keep != Py_None) {
        if (!PyBytes_Check(keep) || PyBytes_GET_SIZE(keep) != STANDARD_ID_BITMAP_BYTES) {
            PyErr_SetString(PyExc_TypeError, "keep must be None or a 512-byte ID bitmap");
            return NULL;
        }
        keep_bits = (const unsigned char *)PyBytes_AS_STRING(keep);
    }
    if (PyUnicode_KIND(text) != PyUnicode_1BYTE_KIND)
        Py_RETURN_NONE;   /* characters beyond Latin-1: the Python path takes the whole text */
    PyObject *items = PyList_New(0);
    if (!items)
        return NULL;
    PyTypeObject *type = (PyTypeObject *)frame_type;
    const char *s = (const char *)PyUnicode_DATA(text);
    const Py_ssize_t n = PyUnicode_GET_LENGTH(text);
    Py_ssize_t skipped = 0, slow_lines = 0;
    double lead_time = Py_NAN, tail_time = Py_NAN;
    int any_frame_line = 0;
    const char *tail_line = NULL;   /* the last frame line, when it is a common one */
    CandumpLine tail;
    Py_ssize_t start = 0;
    while (start < n) {
        const char *newline = memchr(s + start, '\n', (size_t)(n - start));
        const Py_ssize_t end = newline ? (newline - s) + 1 : n;
        const char *line_s = s + start;
        const Py_ssize_t len = end - start;
        start = end;
        CandumpLine line;
        PyObject *item = NULL;
        if (parse_line(line_s, len, &line)) {
            if (!any_frame_line) {
                lead_time = line_time(line_s, &line);
                if (lead_time == -1.0 && PyErr_Occurred())
                    goto fail;
            }
            any_frame_line = 1;
            tail_line = line_s;
            tail = line;
            if (keep_bits && line.id_len <= 3 && !(keep_bits[line.can_id >> 3] & (1u << (line.can_id & 7)))) {
                skipped++;
                continue;
            }
            item = new_frame(type, line_s, &line);
        } else if (is_blank(line_s, len)) {
            continue;
        } else {
            any_frame_line = 1;
            tail_line = NULL;
            slow_lines++;
            item = PyUnicode_FromKindAndData(PyUnicode_1BYTE_KIND, line_s, len);
        }
        if (!item || PyList_Append(items, item) < 0) {
            Py_XDECREF(item);
            goto fail;
        }
        Py_DECREF(item);
    }
    if (tail_line) {
        tail_time = line_time(tail_line, &tail);
        if (tail_time == -1.0 && PyErr_Occurred())
            goto fail;
    }
    return Py_BuildValue("(Nnndd)", items, slow_lines, skipped, lead_time, tail_time);
fail:
    Py_DECREF(items);
    return NULL;
}

static PyMethodDef methods[] = {
    {"candump_frame", py_candump_frame, METH_VARARGS,
     "candump_frame(line, frame_type) -> Frame | None: a candump -L line holding a classical data\n"
     "frame, as busio._read_candump reads it; None for any other line."},
    {"candump_lines", py_candump_lines, METH_VARARGS,
     "candump_lines(text, frame_type, keep) -> (items, slow_lines, skipped, lead_time, tail_time):\n"
     "busio._candump_lines compiled. None when text holds characters beyond Latin-1."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_logcore",
                                    "Reading candump log lines, compiled.", -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__logcore(void)
{
    return PyModule_Create(&module);
}
