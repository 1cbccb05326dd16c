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

/* `(time) channel ID#HEX[ R|T]\n?` as _CANDUMP_DATA_LINE matches it; None otherwise. */
static PyObject *py_candump_frame(PyObject *self, PyObject *args)
{
    PyObject *line, *frame_type;
    if (!PyArg_ParseTuple(args, "UO!", &line, &PyType_Type, &frame_type))
        return NULL;
    if (!PyUnicode_IS_ASCII(line))
        Py_RETURN_NONE;
    const char *s = (const char *)PyUnicode_DATA(line);
    const Py_ssize_t n = PyUnicode_GET_LENGTH(line);
    Py_ssize_t i = 0;
    if (i >= n || s[i] != '(')
        Py_RETURN_NONE;
    const Py_ssize_t time_start = ++i;
    if (i < n && s[i] == '-')
        i++;
    const Py_ssize_t int_start = i;
    while (i < n && is_digit(s[i]))
        i++;
    if (i == int_start || i >= n || s[i] != '.')
        Py_RETURN_NONE;
    const Py_ssize_t frac_start = ++i;
    while (i < n && is_digit(s[i]))
        i++;
    if (i == frac_start || i + 1 >= n || s[i] != ')' || s[i + 1] != ' ')
        Py_RETURN_NONE;
    const Py_ssize_t time_len = i - time_start;
    if (time_len > MAX_TIME_CHARS)
        Py_RETURN_NONE;
    char time_text[MAX_TIME_CHARS + 1];
    memcpy(time_text, s + time_start, (size_t)time_len);
    time_text[time_len] = '\0';
    i += 2;
    const Py_ssize_t channel_start = i;   /* [!-~]+ then one space */
    while (i < n && s[i] >= '!' && s[i] <= '~')
        i++;
    if (i == channel_start || i >= n || s[i] != ' ')
        Py_RETURN_NONE;
    const Py_ssize_t id_start = ++i;
    unsigned long can_id = 0;
    while (i < n && hex_value(s[i]) >= 0 && i - id_start < 8)
        can_id = (can_id << 4) | (unsigned long)hex_value(s[i++]);
    const Py_ssize_t id_len = i - id_start;
    if (id_len == 0 || i >= n || s[i] != '#')
        Py_RETURN_NONE;
    const Py_ssize_t data_start = ++i;
    while (i < n && hex_value(s[i]) >= 0)
        i++;
    const Py_ssize_t data_len = i - data_start;
    if (i + 1 < n && s[i] == ' ' && (s[i + 1] == 'R' || s[i + 1] == 'r' || s[i + 1] == 'T' || s[i + 1] == 't'))
        i += 2;
    if (i < n && s[i] == '\n')
        i++;
    if (i != n || (can_id & 0x20000000UL) || (data_len & 1))
        Py_RETURN_NONE;   /* trailing text, an error frame, half a byte: the Python path */

    unsigned char data[64];
    PyObject *payload;
    if (data_len / 2 <= (Py_ssize_t)sizeof data) {
        for (Py_ssize_t k = 0; k < data_len / 2; k++)
            data[k] = (unsigned char)(hex_value(s[data_start + 2 * k]) << 4 | hex_value(s[data_start + 2 * k + 1]));
        payload = PyBytes_FromStringAndSize((const char *)data, data_len / 2);
    } else {
        payload = PyBytes_FromStringAndSize(NULL, data_len / 2);
        if (payload) {
            char *out = PyBytes_AS_STRING(payload);
            for (Py_ssize_t k = 0; k < data_len / 2; k++)
                out[k] = (char)(hex_value(s[data_start + 2 * k]) << 4 | hex_value(s[data_start + 2 * k + 1]));
        }
    }
    if (!payload)
        return NULL;
    /* float(): the same conversion Python's float() of the text does */
    const double time_s = PyOS_string_to_double(time_text, NULL, NULL);
    if (time_s == -1.0 && PyErr_Occurred()) {
        Py_DECREF(payload);
        return NULL;
    }
    PyObject *items = Py_BuildValue("(dkNOOO)", time_s, can_id & 0x1FFFFFFFUL, payload,
                                    id_len > 3 ? Py_True : Py_False, Py_False, Py_False);
    if (!items)
        return NULL;
    /* tuple.__new__(Frame, items): a Frame without its Python-level __new__ */
    PyObject *new_args = PyTuple_Pack(1, items);
    Py_DECREF(items);
    if (!new_args)
        return NULL;
    PyObject *frame = PyTuple_Type.tp_new((PyTypeObject *)frame_type, new_args, NULL);
    Py_DECREF(new_args);
    return frame;
}

static PyMethodDef methods[] = {
    {"candump_frame", py_candump_frame, METH_VARARGS,
     "candump_frame(line, frame_type) -> Frame | None: a candump -L line holding a classical data\n"
     "frame, as busio._read_candump reads it; None for any other line."},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_logcore",
                                    "Reading candump log lines, compiled.", -1, methods, NULL, NULL, NULL, NULL};

PyMODINIT_FUNC PyInit__logcore(void)
{
    return PyModule_Create(&module);
}
