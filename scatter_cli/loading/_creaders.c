/* Compiled readers for text mesh formats: OBJ, OFF, the body of an ASCII PLY, ASCII STL.
 *
 * Each reader accepts a strict subset of its format and gives the arrays trimesh gives
 * with process=False for it (the rules are in docs/loading.md); for anything outside the
 * subset it returns None and the caller hands the file to trimesh. The input is any
 * buffer (a read-only mapping of the file): no reader reads past its end or needs a final
 * newline. Numbers: a strict decimal grammar, converted with correct rounding (exact
 * small cases directly, the rest by strtod on a copy of the token).
 */
#define PY_SSIZE_T_CLEAN
#include <Python.h>
#define NPY_NO_DEPRECATED_API NPY_1_7_API_VERSION
#include <numpy/arrayobject.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <math.h>
#include "_cthreads.h"

#define MAX_INDEX 2147483647LL
#define MAX_CORNERS 255
#define MAX_MATERIALS 4096
#define MIN_PART (1 << 20) /* bytes a part of a text read on several threads at least */

typedef struct {
    const char *p, *end;
} cursor;

/* ---- growing arrays ---- */
typedef struct {
    char *data;
    size_t len, cap; /* bytes */
} grow;

static int grow_room(grow *g, size_t more)
{
    if (g->len + more <= g->cap)
        return 0;
    size_t cap = g->cap ? g->cap : 4096;
    while (cap < g->len + more) {
        if (cap > SIZE_MAX / 2)
            return -1;
        cap *= 2;
    }
    char *d = realloc(g->data, cap);
    if (!d)
        return -1;
    g->data = d;
    g->cap = cap;
    return 0;
}

static void grow_free(grow *g)
{
    free(g->data);
    g->data = NULL;
    g->len = g->cap = 0;
}

/* Where the next of ``left`` parts of [from, end) ends, for a text read in parts on
 * several threads: just after a '\n' (so each part starts a line), parts of MIN_PART bytes
 * or more, the last at ``end``. */
static const char *next_cut(const char *from, const char *end, int left)
{
    if (left > 1 && (end - from) / left >= MIN_PART) {
        const char *nl = memchr(from + (end - from) / left, '\n', (size_t)(end - from - (end - from) / left));
        return nl ? nl + 1 : end;
    }
    return end;
}

static void free_capsule(PyObject *cap)
{
    free(PyCapsule_GetPointer(cap, NULL));
}

/* An ndarray of `rows` x `cols` owning `data` (malloc'd; freed with the array). Takes
 * `data` in every case. */
static PyObject *owned_array(void *data, npy_intp rows, npy_intp cols, int type)
{
    npy_intp dims[2] = {rows, cols};
    if (!data) {
        data = malloc(1);
        if (!data)
            return PyErr_NoMemory();
    }
    PyObject *arr = PyArray_SimpleNewFromData(2, dims, type, data);
    if (!arr) {
        free(data);
        return NULL;
    }
    PyObject *cap = PyCapsule_New(data, NULL, free_capsule);
    if (!cap) {
        free(data);
        Py_DECREF(arr);
        return NULL;
    }
    if (PyArray_SetBaseObject((PyArrayObject *)arr, cap) < 0) {
        Py_DECREF(arr);
        return NULL;
    }
    return arr;
}

/* ---- characters and numbers ---- */
static inline int is_space(char c) { return c == ' ' || c == '\t'; }
static inline int is_digit(char c) { return c >= '0' && c <= '9'; }
static inline int is_break(char c) { return c == '\n' || c == '\r'; }

static void skip_spaces(cursor *c)
{
    while (c->p < c->end && is_space(*c->p))
        c->p++;
}

static inline int at_token_end(const cursor *c)
{
    return c->p >= c->end || is_space(*c->p) || is_break(*c->p);
}

static const double POW10[23] = {1e0,  1e1,  1e2,  1e3,  1e4,  1e5,  1e6,  1e7,  1e8,  1e9,  1e10, 1e11,
                                 1e12, 1e13, 1e14, 1e15, 1e16, 1e17, 1e18, 1e19, 1e20, 1e21, 1e22};

static const uint64_t POW10_INT[20] = {1ULL, 10ULL, 100ULL, 1000ULL, 10000ULL, 100000ULL, 1000000ULL,
                                       10000000ULL, 100000000ULL, 1000000000ULL, 10000000000ULL,
                                       100000000000ULL, 1000000000000ULL, 10000000000000ULL,
                                       100000000000000ULL, 1000000000000000ULL, 10000000000000000ULL,
                                       100000000000000000ULL, 1000000000000000000ULL,
                                       10000000000000000000ULL};

static int bits128(unsigned __int128 x)
{
    uint64_t hi = (uint64_t)(x >> 64), lo = (uint64_t)x;
    return hi ? 128 - __builtin_clzll(hi) : lo ? 64 - __builtin_clzll(lo) : 0;
}

/* 2^e as a double, for -1022 <= e <= 1023: a product by it is exact (ldexp's cost without its checks). */
static inline double power_of_two(int e)
{
    uint64_t bits = (uint64_t)(e + 1023) << 52;
    double d;
    memcpy(&d, &bits, sizeof d);
    return d;
}

/* m * 10^e10 rounded to the nearest double (ties to even), for 0 < m < 2^64 and
 * |e10| <= 19, with exact 128-bit integers: a product, or a quotient in [2^62, 2^64)
 * (so one 128-by-64-bit division step) and a remainder for the sticky bit. */
static double exact_decimal(uint64_t m, int e10)
{
    unsigned __int128 q;
    int shift = 0, inexact = 0;
    if (e10 >= 0) {
        q = (unsigned __int128)m * POW10_INT[e10];
    } else {
        uint64_t d = POW10_INT[-e10];
        shift = 63 + __builtin_clzll(m) - __builtin_clzll(d); /* n in [2^62 d, 2^64 d) */
        unsigned __int128 n = (unsigned __int128)m << shift;
        q = n / d;
        inexact = n % d != 0;
    }
    int drop = bits128(q) - 53;
    if (drop > 0) {
        unsigned __int128 low = q & ((((unsigned __int128)1) << drop) - 1), half = ((unsigned __int128)1) << (drop - 1);
        q >>= drop;
        if (low > half || (low == half && (inexact || (q & 1))))
            q++;
        if (q >> 53) {
            q >>= 1;
            drop++;
        }
    } else {
        drop = 0;
    }
    return (double)(uint64_t)q * power_of_two(drop - shift); /* q < 2^53: exact, and a normal result */
}

/* Eight ASCII digits at p (p + 8 within the buffer): 1 and their value in *out, else 0.
 * Bit tricks on one little-endian 64-bit load (as fast_float does). */
static inline int eight_digits(const char *p, uint64_t *out)
{
    uint64_t x;
    memcpy(&x, p, 8);
    if (((x + 0x4646464646464646ULL) | (x - 0x3030303030303030ULL)) & 0x8080808080808080ULL)
        return 0;
    x -= 0x3030303030303030ULL;
    x = (x * 10) + (x >> 8);
    x = (((x & 0x000000FF000000FFULL) * 0x000F424000000064ULL) +
         (((x >> 16) & 0x000000FF000000FFULL) * 0x0000271000000001ULL)) >> 32;
    *out = (uint32_t)x;
    return 1;
}

/* A decimal number at c->p ([+-]? digits [. digits] [e [+-] digits], a digit somewhere
 * before the exponent), ending at whitespace, a line break or the end. 0 and the value
 * in *out, or -1 (not such a number; c->p then undefined). */
static int parse_double(cursor *c, double *out)
{
    const char *start = c->p, *p = c->p, *end = c->end;
    int negative = 0;
    if (p < end && (*p == '+' || *p == '-'))
        negative = *p++ == '-';
    uint64_t mantissa = 0;
    int significant = 0, digits = 0, scale = 0;
    uint64_t eight;
    while (p < end && is_digit(*p)) {
        if ((mantissa || *p != '0') && significant <= 11 && end - p >= 8 && eight_digits(p, &eight)) {
            mantissa = mantissa * 100000000ULL + eight;
            significant += 8;
            digits += 8;
            p += 8;
            continue;
        }
        if (mantissa || *p != '0') {
            if (significant < 19)
                mantissa = mantissa * 10 + (uint64_t)(*p - '0');
            else
                scale++;
            significant++;
        }
        digits++;
        p++;
    }
    if (p < end && *p == '.') {
        p++;
        while (p < end && is_digit(*p)) {
            if ((mantissa || *p != '0') && significant <= 11 && end - p >= 8 && eight_digits(p, &eight)) {
                mantissa = mantissa * 100000000ULL + eight;
                significant += 8;
                scale -= 8;
                digits += 8;
                p += 8;
                continue;
            }
            if (mantissa || *p != '0') {
                if (significant < 19) {
                    mantissa = mantissa * 10 + (uint64_t)(*p - '0');
                    scale--;
                }
                significant++;
            } else {
                scale--;
            }
            digits++;
            p++;
        }
    }
    if (!digits)
        return -1;
    long exponent = 0;
    if (p < end && (*p == 'e' || *p == 'E')) {
        p++;
        int eneg = 0;
        if (p < end && (*p == '+' || *p == '-'))
            eneg = *p++ == '-';
        if (p >= end || !is_digit(*p))
            return -1;
        while (p < end && is_digit(*p)) {
            if (exponent < 100000000)
                exponent = exponent * 10 + (*p - '0');
            p++;
        }
        if (eneg)
            exponent = -exponent;
    }
    c->p = p;
    if (!at_token_end(c))
        return -1;
    long e10 = exponent + scale;
    if (mantissa == 0) {
        *out = negative ? -0.0 : 0.0;
        return 0;
    }
    if (significant <= 19 && mantissa <= (1ULL << 53) && e10 >= -22 && e10 <= 22) {
        double m = (double)mantissa; /* exact */
        double v = e10 < 0 ? m / POW10[-e10] : m * POW10[e10];
        *out = negative ? -v : v;
        return 0;
    }
    if (significant <= 19 && e10 >= -19 && e10 <= 19) {
        double v = exact_decimal(mantissa, (int)e10);
        *out = negative ? -v : v;
        return 0;
    }
    /* the general case: strtod on a NUL-terminated copy of the token */
    size_t n = (size_t)(p - start);
    char small[128];
    char *copy = n < sizeof small ? small : malloc(n + 1);
    if (!copy)
        return -1;
    memcpy(copy, start, n);
    copy[n] = 0;
    char *stop;
    *out = strtod(copy, &stop);
    int ok = stop == copy + n;
    if (copy != small)
        free(copy);
    return ok ? 0 : -1;
}

/* An integer [-]digits at c->p, |value| <= MAX_INDEX, then a token end unless `more`
 * names the one character allowed to follow ('/'). */
static int parse_int(cursor *c, int64_t *out, char more)
{
    const char *p = c->p, *end = c->end;
    int negative = 0;
    if (p < end && *p == '-') {
        negative = 1;
        p++;
    }
    if (p >= end || !is_digit(*p))
        return -1;
    int64_t v = 0;
    while (p < end && is_digit(*p)) {
        v = v * 10 + (*p - '0');
        if (v > MAX_INDEX)
            return -1;
        p++;
    }
    c->p = p;
    if (!(at_token_end(c) || (more && p < end && *p == more)))
        return -1;
    *out = negative ? -v : v;
    return 0;
}

/* The line ends here (spaces, then a break or the end): 0, moving past the break. */
static int end_line(cursor *c)
{
    skip_spaces(c);
    if (c->p >= c->end)
        return 0;
    if (*c->p == '\r') {
        c->p++;
        if (c->p < c->end && *c->p == '\n')
            c->p++;
        return 0;
    }
    if (*c->p == '\n') {
        c->p++;
        return 0;
    }
    return -1;
}

/* 1 for a byte other than tab, LF, CR and printable ASCII: such bytes mean decoding,
 * Unicode line breaks or whitespace that only trimesh's own handling decides. */
static inline unsigned char not_plain(unsigned char b)
{
    unsigned char control = (unsigned char)(b - 0x20) >= 0x5f; /* below 0x20 or 0x7f and up */
    return control & (b != '\t') & (b != '\n') & (b != '\r');
}

/* Only plain bytes (see not_plain). */
static int plain_text(const char *s, Py_ssize_t n)
{
    const unsigned char *u = (const unsigned char *)s;
    for (Py_ssize_t i = 0; i < n;) {
        Py_ssize_t stop = n - i > 4096 ? i + 4096 : n;
        unsigned char bad = 0;
        for (; i < stop; i++) /* no early exit inside a block: the compiler vectorises it */
            bad |= not_plain(u[i]);
        if (bad)
            return 0;
    }
    return 1;
}

static const char *find(const char *hay, size_t n, const char *needle)
{
    return memmem(hay, n, needle, strlen(needle));
}

/* ---- OBJ ---- */

typedef struct {
    grow v;       /* double x3 per vertex */
    grow refs;    /* int32 per corner, as written (1-based or negative) */
    grow corners; /* uint8 per face line */
    grow runs;    /* run: a stretch of face lines under one material */
    const char *names[MAX_MATERIALS];
    size_t name_len[MAX_MATERIALS];
    int64_t group_lines[MAX_MATERIALS], group_min[MAX_MATERIALS], group_max[MAX_MATERIALS];
    int64_t group_cmin[MAX_MATERIALS], group_cmax[MAX_MATERIALS]; /* numbers on a face line */
    int group_forms[MAX_MATERIALS];                                /* bit per ref form seen */
    int groups;
    const char *material; /* the current material, NULL before any usemtl */
    size_t material_len;
    int current; /* its group, -1 until a face uses it */
    int v_cols, vt_cols;
    int attributes;  /* keep the vt and vn refs and values (read_obj's second argument) */
    grow trefs, nrefs; /* int32 per corner: the vt and vn refs as written, 0 when absent */
    grow vt, vn;       /* double x2 (u, v) / x3 per line */
} obj_state;

typedef struct {
    int64_t first_line, first_ref, lines;
    int group;
} run;

/* The numbers on the rest of a line: count; stores the first three in xyz (may be NULL). */
static int numbers(cursor *c, double *xyz)
{
    int n = 0;
    for (;;) {
        skip_spaces(c);
        if (c->p >= c->end || is_break(*c->p))
            return n;
        double d;
        if (parse_double(c, &d) < 0)
            return -1;
        if (xyz && n < 3)
            xyz[n] = d;
        n++;
    }
}

/* The material of a part of a file read in parts (read_obj) until its first usemtl: the
 * one the parts before it leave, known when the parts are joined. */
static const char INHERIT[] = "";

/* Whether two material names are one (NULL: no usemtl yet). */
static int same_name(const char *a, size_t a_len, const char *b, size_t b_len)
{
    if (a == INHERIT || b == INHERIT)
        return a == b;
    return a_len == b_len && (a == b || (a && b && !memcmp(a, b, a_len)));
}

/* The group of material ``name``, made (after the others) when new; -1 past MAX_MATERIALS. */
static int group_named(obj_state *s, const char *name, size_t len)
{
    for (int g = 0; g < s->groups; g++)
        if (same_name(s->names[g], s->name_len[g], name, len))
            return g;
    if (s->groups >= MAX_MATERIALS)
        return -1;
    int g = s->groups++;
    s->names[g] = name;
    s->name_len[g] = len;
    s->group_lines[g] = 0;
    s->group_min[g] = s->group_cmin[g] = 4 * MAX_CORNERS;
    s->group_max[g] = s->group_cmax[g] = 0;
    s->group_forms[g] = 0;
    return g;
}

static int group_of(obj_state *s)
{
    return group_named(s, s->material, s->material_len);
}

/* One ref: v, v/t, v//n or v/t/n (form 0 to 3); tn: the t and n refs (0 when absent). */
static int face_ref(cursor *c, int32_t *vertex, int32_t *tn, int *form_out)
{
    int64_t v, t = 0, n = 0;
    int form = 0;
    if (parse_int(c, &v, '/') < 0)
        return -1;
    if (c->p < c->end && *c->p == '/') {
        c->p++;
        if (c->p < c->end && *c->p == '/') {
            c->p++;
            if (parse_int(c, &n, 0) < 0)
                return -1;
            form = 2;
        } else {
            if (parse_int(c, &t, '/') < 0)
                return -1;
            form = 1;
            if (c->p < c->end && *c->p == '/') {
                c->p++;
                if (parse_int(c, &n, 0) < 0)
                    return -1;
                form = 3;
            }
        }
    }
    if (v == 0)
        return -1;
    *vertex = (int32_t)v;
    tn[0] = (int32_t)t;
    tn[1] = (int32_t)n;
    *form_out = form;
    return 0;
}

static int push_int32(grow *g, int32_t x)
{
    if (grow_room(g, 4) < 0)
        return -1;
    memcpy(g->data + g->len, &x, 4);
    g->len += 4;
    return 0;
}

static int push_doubles(grow *g, const double *x, int n)
{
    if (grow_room(g, (size_t)n * sizeof(double)) < 0)
        return -1;
    memcpy(g->data + g->len, x, (size_t)n * sizeof(double));
    g->len += (size_t)n * sizeof(double);
    return 0;
}

/* 0, 1 to hand off, -1 out of memory. */
static int face_line(cursor *c, obj_state *s, int64_t line)
{
    static const int NUMBERS[4] = {1, 2, 2, 3};
    int k = 0, forms = 0, columns = 0;
    for (;;) {
        skip_spaces(c);
        if (c->p >= c->end || is_break(*c->p))
            break;
        if (k >= MAX_CORNERS)
            return 1;
        if (grow_room(&s->refs, 4) < 0)
            return -1;
        int32_t v, tn[2];
        int form;
        if (face_ref(c, &v, tn, &form) < 0)
            return 1;
        if (s->attributes && (push_int32(&s->trefs, tn[0]) < 0 || push_int32(&s->nrefs, tn[1]) < 0))
            return -1;
        forms |= 1 << form;
        columns += NUMBERS[form];
        memcpy(s->refs.data + s->refs.len, &v, 4);
        s->refs.len += 4;
        k++;
    }
    if (k < 3)
        return 1;
    if (s->current < 0) {
        s->current = group_of(s);
        if (s->current < 0)
            return 1;
    }
    int g = s->current;
    run *last = s->runs.len ? (run *)(s->runs.data + s->runs.len - sizeof(run)) : NULL;
    if (!last || last->group != g) {
        if (grow_room(&s->runs, sizeof(run)) < 0)
            return -1;
        last = (run *)(s->runs.data + s->runs.len);
        last->first_line = line;
        last->first_ref = (int64_t)(s->refs.len / 4) - k;
        last->lines = 0;
        last->group = g;
        s->runs.len += sizeof(run);
    }
    last->lines++;
    if (grow_room(&s->corners, 1) < 0)
        return -1;
    s->corners.data[s->corners.len++] = (char)k;
    s->group_lines[g]++;
    if (k < s->group_min[g])
        s->group_min[g] = k;
    if (k > s->group_max[g])
        s->group_max[g] = k;
    if (columns < s->group_cmin[g])
        s->group_cmin[g] = columns;
    if (columns > s->group_cmax[g])
        s->group_cmax[g] = columns;
    s->group_forms[g] |= forms;
    return 0;
}

static int rest_has_usemtl(cursor *c)
{
    const char *e = memchr(c->p, '\n', (size_t)(c->end - c->p));
    e = e ? e : c->end;
    return find(c->p, (size_t)(e - c->p), "usemtl ") != NULL;
}

static void skip_line(cursor *c)
{
    const char *e = memchr(c->p, '\n', (size_t)(c->end - c->p));
    c->p = e ? e + 1 : c->end;
}

static int starts(const cursor *c, const char *word)
{
    size_t n = strlen(word);
    return (size_t)(c->end - c->p) >= n && !memcmp(c->p, word, n);
}

/* 0 parsed, 1 hand off, -1 out of memory. */
static int obj_lines(cursor *c, obj_state *s)
{
    int64_t line = 0;
    while (c->p < c->end) {
        char ch = *c->p;
        if (is_break(ch)) {
            if (end_line(c) < 0)
                return 1;
            continue;
        }
        if (is_space(ch)) { /* a blank line, or content trimesh would not see */
            skip_spaces(c);
            if (end_line(c) < 0)
                return 1;
            continue;
        }
        if (ch == 'v' && c->end - c->p > 2 && c->p[1] == ' ') { /* the common lines first */
            c->p += 2;
            double xyz[3];
            if (grow_room(&s->v, 3 * sizeof(double)) < 0)
                return -1;
            int n = numbers(c, xyz);
            if (n < 3 || (s->v_cols && n != s->v_cols))
                return 1;
            s->v_cols = n;
            memcpy(s->v.data + s->v.len, xyz, sizeof xyz);
            s->v.len += sizeof xyz;
            if (end_line(c) < 0)
                return 1;
            continue;
        }
        if (ch == 'f' && c->end - c->p > 2 && c->p[1] == ' ') {
            c->p += 2;
            int status = face_line(c, s, line++);
            if (status)
                return status;
            if (end_line(c) < 0)
                return 1;
            continue;
        }
        if (ch == '#' || starts(c, "o ") || starts(c, "g ") || starts(c, "s ") || starts(c, "mtllib ")) {
            if (rest_has_usemtl(c))
                return 1;
            skip_line(c);
            continue;
        }
        if (starts(c, "v ")) {
            c->p += 2;
            double xyz[3];
            if (grow_room(&s->v, 3 * sizeof(double)) < 0)
                return -1;
            int n = numbers(c, xyz);
            if (n < 3 || (s->v_cols && n != s->v_cols))
                return 1;
            s->v_cols = n;
            memcpy(s->v.data + s->v.len, xyz, sizeof xyz);
            s->v.len += sizeof xyz;
        } else if (starts(c, "vt ")) {
            c->p += 3;
            double uvw[3];
            int n = numbers(c, uvw);
            if (n < 2 || n > 3 || (s->vt_cols && n != s->vt_cols))
                return 1;
            s->vt_cols = n;
            if (s->attributes && push_doubles(&s->vt, uvw, 2) < 0) /* trimesh keeps u, v */
                return -1;
        } else if (starts(c, "vn ")) {
            c->p += 3;
            double xyz[3];
            if (numbers(c, xyz) != 3)
                return 1;
            if (s->attributes && push_doubles(&s->vn, xyz, 3) < 0)
                return -1;
        } else if (starts(c, "f ")) {
            c->p += 2;
            int status = face_line(c, s, line++);
            if (status)
                return status;
        } else if (starts(c, "usemtl ")) {
            c->p += 7;
            if (rest_has_usemtl(c))
                return 1;
            skip_spaces(c);
            const char *a = c->p, *e = memchr(c->p, '\n', (size_t)(c->end - c->p));
            e = e ? e : c->end;
            while (e > a && (is_space(e[-1]) || e[-1] == '\r'))
                e--;
            s->material = a;
            s->material_len = (size_t)(e - a);
            s->current = -1;
            skip_line(c);
            continue;
        } else {
            return 1; /* l, p, curves, v\t...: trimesh decides */
        }
        if (end_line(c) < 0)
            return 1;
    }
    return 0;
}

/* The CRLF and backslash-newline rules as trimesh applies them: every CR must begin a
 * CRLF; CRLF becomes LF, then each backslash-LF goes (two left-to-right passes, as two
 * str.replace calls). Returns the new length, or -1 for a lone CR. */
static Py_ssize_t normalise(char *t, Py_ssize_t n)
{
    Py_ssize_t w = 0;
    for (Py_ssize_t r = 0; r < n; r++) {
        if (t[r] == '\r') {
            if (r + 1 >= n || t[r + 1] != '\n')
                return -1;
            continue;
        }
        t[w++] = t[r];
    }
    n = w;
    w = 0;
    for (Py_ssize_t r = 0; r < n; r++) {
        if (t[r] == '\\' && r + 1 < n && t[r + 1] == '\n') {
            r++;
            continue;
        }
        t[w++] = t[r];
    }
    return w;
}

static int64_t resolve(int32_t r, int64_t nv)
{
    int64_t i = r > 0 ? (int64_t)r - 1 : nv + r;
    return (i >= 0 && i < nv) ? i : -1;
}

/* The key trimesh's unmerge_faces sorts a corner's (v, vt, vn) refs by (form 1: v, vt;
 * 2: v, vn; 3: v, vt, vn), each as trimesh holds it (1-based made 0-based, negative kept):
 * grouping.hashable_rows packs the columns into one uint64, `precision` bits each, offset
 * by the threshold. Returns 0 where a ref is outside that packing (trimesh then hashes
 * the rows' bytes, which sort otherwise: hand off). */
static int corner_key(int form, int32_t v, int32_t t, int32_t n, uint64_t *key)
{
    int64_t cols[3], k = 0;
    cols[k++] = v > 0 ? (int64_t)v - 1 : v;
    if (form & 1)
        cols[k++] = t > 0 ? (int64_t)t - 1 : t;
    if (form & 2)
        cols[k++] = n > 0 ? (int64_t)n - 1 : n;
    int precision = (int)(64 / k);
    int64_t threshold = ((int64_t)1 << (precision - 1)) - 1;
    uint64_t h = 0;
    for (int64_t j = 0; j < k; j++) {
        if (!(cols[j] < threshold && cols[j] > -threshold))
            return 0;
        h ^= (uint64_t)(cols[j] + threshold + 1) << (j * precision);
    }
    *key = h;
    return 1;
}

/* Triangles of one material group in trimesh's order, appended at out (int64 x3), or
 * NULL to hand off. When every face line of the group holds as many numbers, trimesh
 * reads them as one array (then all quads give every first triangle, then every second;
 * mixed ref forms would be misread, so those go to trimesh); else line by line (a quad
 * gives its two triangles in turn). Larger polygons are fans either way. */
static int64_t *emit_group(obj_state *s, int g, const int32_t *refs, int64_t nv, int64_t *out)
{
    const run *runs = (const run *)s->runs.data;
    size_t nruns = s->runs.len / sizeof(run);
    const uint8_t *corners = (const uint8_t *)s->corners.data;
    int flat = s->group_cmin[g] == s->group_cmax[g];
    int forms = s->group_forms[g];
    if ((flat || s->attributes) && (forms & (forms - 1)))
        return NULL;
    /* attributes: a group whose refs carry vt or vn gives each corner's key instead */
    int form = 0;
    while (s->attributes && forms >> form > 1)
        form++;
    const int32_t *trefs = (const int32_t *)s->trefs.data, *nrefs = (const int32_t *)s->nrefs.data;
    int passes = (flat && s->group_max[g] == 4) ? 2 : 1; /* all quads: first halves, then second */
    for (int pass = 0; pass < passes; pass++) {
        for (size_t r = 0; r < nruns; r++) {
            if (runs[r].group != g)
                continue;
            const int32_t *f = refs + runs[r].first_ref;
            for (int64_t l = 0; l < runs[r].lines; l++) {
                int k = corners[runs[r].first_line + l];
                int64_t idx[MAX_CORNERS];
                for (int j = 0; j < k; j++) {
                    idx[j] = resolve(f[j], nv);
                    if (idx[j] < 0)
                        return NULL;
                    if (form) {
                        int64_t at = f - refs + j;
                        uint64_t key;
                        if (!corner_key(form, f[j], trefs[at], nrefs[at], &key))
                            return NULL;
                        memcpy(&idx[j], &key, 8);
                    }
                }
                if (passes == 2) {
                    int a = pass ? 2 : 0, b = pass ? 3 : 1, cc = pass ? 0 : 2;
                    *out++ = idx[a], *out++ = idx[b], *out++ = idx[cc];
                } else if (k == 4) { /* a quad read line by line */
                    *out++ = idx[0], *out++ = idx[1], *out++ = idx[2];
                    *out++ = idx[2], *out++ = idx[3], *out++ = idx[0];
                } else {
                    for (int j = 1; j + 1 < k; j++)
                        *out++ = idx[0], *out++ = idx[j], *out++ = idx[j + 1];
                }
                f += k;
            }
        }
    }
    return out;
}

/* An OBJ read in parts on several threads (its text cut at line breaks, next_cut): each
 * part is read as one pass reads the whole, into a state of its own whose material starts
 * as INHERIT; then the parts are joined in file order into the first one's state, as one
 * pass would have made it. The refs are kept as written (resolved against the file's
 * vertex count at the end, as one pass does), so no part needs the counts before it; a
 * part's groups are renamed to the file's (INHERIT: the material the parts before leave),
 * made in the order the faces first use them; its runs of face lines move on by the lines
 * and refs before it, the first joining the last before it when their group is one. */
typedef struct {
    const char *p, *stop;
    obj_state *s;
    int status;
} obj_part;

static void obj_part_run(void *ctx, int k, int count)
{
    obj_part *part = (obj_part *)ctx + k;
    cursor c = {part->p, part->stop};
    (void)count;
    part->status = obj_lines(&c, part->s);
}

/* g's bytes appended to to (g freed): 0, or -1 out of memory. */
static int append(grow *to, grow *g)
{
    if (g->len) {
        if (grow_room(to, g->len) < 0)
            return -1;
        memcpy(to->data + to->len, g->data, g->len);
        to->len += g->len;
    }
    grow_free(g);
    return 0;
}

/* Part p's state onto s, the parts before it already there; *carried, *carried_len: the
 * material in effect after them (updated). 0, 1 (hand off) or -1 (out of memory). */
static int join_obj(obj_state *s, obj_state *p, const char **carried, size_t *carried_len)
{
    if (p->v_cols && s->v_cols && p->v_cols != s->v_cols)
        return 1; /* one pass: every v line as long as the first */
    s->v_cols = s->v_cols ? s->v_cols : p->v_cols;
    if (p->vt_cols && s->vt_cols && p->vt_cols != s->vt_cols)
        return 1;
    s->vt_cols = s->vt_cols ? s->vt_cols : p->vt_cols;
    int map[MAX_MATERIALS];
    for (int g = 0; g < p->groups; g++) {
        int inherit = p->names[g] == INHERIT;
        int h = group_named(s, inherit ? *carried : p->names[g], inherit ? *carried_len : p->name_len[g]);
        if (h < 0)
            return 1;
        map[g] = h;
        s->group_lines[h] += p->group_lines[g];
        s->group_min[h] = p->group_min[g] < s->group_min[h] ? p->group_min[g] : s->group_min[h];
        s->group_max[h] = p->group_max[g] > s->group_max[h] ? p->group_max[g] : s->group_max[h];
        s->group_cmin[h] = p->group_cmin[g] < s->group_cmin[h] ? p->group_cmin[g] : s->group_cmin[h];
        s->group_cmax[h] = p->group_cmax[g] > s->group_cmax[h] ? p->group_cmax[g] : s->group_cmax[h];
        s->group_forms[h] |= p->group_forms[g];
    }
    int64_t lines = (int64_t)s->corners.len, refs = (int64_t)(s->refs.len / 4);
    const run *r = (const run *)p->runs.data;
    for (size_t j = 0; j < p->runs.len / sizeof(run); j++) {
        run *last = s->runs.len ? (run *)(s->runs.data + s->runs.len - sizeof(run)) : NULL;
        if (last && last->group == map[r[j].group]) {
            last->lines += r[j].lines;
            continue;
        }
        if (grow_room(&s->runs, sizeof(run)) < 0)
            return -1;
        run moved = {r[j].first_line + lines, r[j].first_ref + refs, r[j].lines, map[r[j].group]};
        memcpy(s->runs.data + s->runs.len, &moved, sizeof moved);
        s->runs.len += sizeof moved;
    }
    grow *to[7] = {&s->v, &s->refs, &s->corners, &s->trefs, &s->nrefs, &s->vt, &s->vn};
    grow *from[7] = {&p->v, &p->refs, &p->corners, &p->trefs, &p->nrefs, &p->vt, &p->vn};
    for (int k = 0; k < 7; k++)
        if (append(to[k], from[k]) < 0)
            return -1;
    if (p->material != INHERIT)
        *carried = p->material, *carried_len = p->material_len;
    return 0;
}

static void obj_state_free(obj_state *s)
{
    grow *all[9] = {&s->v, &s->trefs, &s->nrefs, &s->vt, &s->vn, &s->refs, &s->corners, &s->runs, NULL};
    for (int k = 0; all[k]; k++)
        grow_free(all[k]);
    free(s);
}

/* The text [text, text + n) into s (the first part's state), in parts on ``threads``
 * threads: 0, 1 (hand off) or -1 (out of memory), as one pass would say but for which of
 * two failures. */
static int obj_in_parts(const char *text, Py_ssize_t n, obj_state *s, int threads)
{
    int most = pieces_for(n, MIN_PART, threads);
    if (most <= 1) {
        cursor c = {text, text + n};
        return obj_lines(&c, s);
    }
    obj_part *parts = calloc((size_t)most, sizeof *parts);
    int count = 0, status = parts ? 0 : -1;
    for (const char *p = text; !status && (count == 0 || (p < text + n && count < most)); p = parts[count++].stop) {
        obj_state *own = count ? calloc(1, sizeof(obj_state)) : s;
        if (!own) {
            status = -1;
            break;
        }
        if (count) {
            own->current = -1, own->attributes = s->attributes;
            own->material = INHERIT, own->material_len = 0;
        }
        parts[count] = (obj_part){p, next_cut(p, text + n, most - count), own, 1};
    }
    if (!status) {
        in_pieces(count, threads, obj_part_run, parts);
        for (int k = 0; k < count && !status; k++)
            status = parts[k].status; /* the first failure in file order */
        const char *carried = s->material;
        size_t carried_len = s->material_len;
        for (int k = 1; k < count && !status; k++)
            status = join_obj(s, parts[k].s, &carried, &carried_len);
    }
    for (int k = 1; parts && k < count; k++)
        if (parts[k].s)
            obj_state_free(parts[k].s);
    free(parts);
    return status;
}

static PyObject *read_obj(PyObject *self, PyObject *args)
{
    Py_buffer buf;
    int attributes = 0, threads = 1;
    if (!PyArg_ParseTuple(args, "y*|pi", &buf, &attributes, &threads))
        return NULL;
    const char *text = buf.buf;
    Py_ssize_t n = buf.len;
    char *copy = NULL;
    PyObject *result = NULL;
    obj_state *s = calloc(1, sizeof(obj_state));
    if (!s) {
        PyBuffer_Release(&buf);
        return PyErr_NoMemory();
    }
    s->current = -1;
    s->attributes = attributes;
    int status = 1;
    Py_BEGIN_ALLOW_THREADS
    if (plain_text(text, n)) {
        status = 0;
        if (memchr(text, '\r', (size_t)n) || memchr(text, '\\', (size_t)n)) {
            copy = malloc((size_t)n + 1);
            if (!copy)
                status = -1;
            else {
                memcpy(copy, text, (size_t)n);
                n = normalise(copy, n);
                text = copy;
                if (n < 0)
                    status = 1;
            }
        }
        if (!status)
            status = obj_in_parts(text, n, s, threads);
    }
    Py_END_ALLOW_THREADS
    if (status < 0) {
        PyErr_NoMemory();
        goto done;
    }
    int64_t nv = (int64_t)(s->v.len / (3 * sizeof(double)));
    if (status || !s->corners.len || !nv) {
        result = Py_None;
        Py_INCREF(result);
        goto done;
    }
    int64_t nf = 0;
    for (size_t i = 0; i < s->corners.len; i++)
        nf += (uint8_t)s->corners.data[i] - 2;
    int64_t *faces = malloc((size_t)nf * 3 * sizeof(int64_t) + 1);
    PyObject *counts = PyList_New(0), *forms = PyList_New(0);
    if (!faces || !counts || !forms) {
        free(faces);
        Py_XDECREF(counts);
        Py_XDECREF(forms);
        PyErr_NoMemory();
        goto done;
    }
    int64_t *out = faces;
    for (int g = s->groups - 1; g >= 0; g--) { /* trimesh builds the last material first */
        int64_t *next = emit_group(s, g, (const int32_t *)s->refs.data, nv, out);
        if (!next) {
            free(faces);
            Py_DECREF(counts);
            Py_DECREF(forms);
            result = Py_None;
            Py_INCREF(result);
            goto done;
        }
        PyObject *k = PyLong_FromLongLong((next - out) / 3);
        PyObject *form = PyLong_FromLong(s->group_forms[g]);
        if (!k || !form || PyList_Append(counts, k) < 0 || PyList_Append(forms, form) < 0) {
            Py_XDECREF(k);
            Py_XDECREF(form);
            free(faces);
            Py_DECREF(counts);
            Py_DECREF(forms);
            goto done;
        }
        Py_DECREF(k);
        Py_DECREF(form);
        out = next;
    }
    PyObject *v = owned_array(s->v.data, nv, 3, NPY_FLOAT64);
    s->v.data = NULL;
    PyObject *f = owned_array(faces, nf, 3, NPY_INT64);
    if (v && f && !attributes) {
        result = Py_BuildValue("(NNN)", v, f, counts);
        Py_DECREF(forms);
    } else if (v && f) {
        PyObject *vt = owned_array(s->vt.data, (npy_intp)(s->vt.len / 16), 2, NPY_FLOAT64);
        s->vt.data = NULL;
        PyObject *vn = owned_array(s->vn.data, (npy_intp)(s->vn.len / 24), 3, NPY_FLOAT64);
        s->vn.data = NULL;
        if (vt && vn)
            result = Py_BuildValue("(NNNNNN)", v, f, counts, forms, vt, vn);
        else {
            Py_XDECREF(vt);
            Py_XDECREF(vn);
            Py_DECREF(v);
            Py_DECREF(f);
            Py_DECREF(counts);
            Py_DECREF(forms);
        }
    } else {
        Py_XDECREF(v);
        Py_XDECREF(f);
        Py_DECREF(counts);
        Py_DECREF(forms);
    }
done:
    grow_free(&s->v);
    grow_free(&s->trefs);
    grow_free(&s->nrefs);
    grow_free(&s->vt);
    grow_free(&s->vn);
    grow_free(&s->refs);
    grow_free(&s->corners);
    grow_free(&s->runs);
    free(s);
    free(copy);
    PyBuffer_Release(&buf);
    return result;
}

/* ---- OFF and ASCII PLY: counted vertex and face lines ---- */

/* Past blank lines (the OFF reader drops them). */
static void skip_blank_lines(cursor *c)
{
    for (;;) {
        const char *p = c->p;
        skip_spaces(c);
        if (c->p < c->end && is_break(*c->p)) {
            end_line(c);
            continue;
        }
        if (c->p >= c->end)
            return;
        c->p = p;
        skip_spaces(c);
        return;
    }
}

/* Polygon lists: triangles in file order, then every quad's first triangle, then every
 * quad's second (trimesh's triangulate_quads); polygons of five or more corners only when
 * every face has the same count (then fans, face by face). idx holds k corners a face. */
typedef struct {
    grow tri, quad, poly; /* int64 x3 / x4 / xk */
    int64_t kmin, kmax;
} polys;

static int add_face(polys *q, const int64_t *idx, int k)
{
    grow *g = k == 3 ? &q->tri : k == 4 ? &q->quad : &q->poly;
    if (grow_room(g, (size_t)k * 8) < 0)
        return -1;
    memcpy(g->data + g->len, idx, (size_t)k * 8);
    g->len += (size_t)k * 8;
    if (k < q->kmin)
        q->kmin = k;
    if (k > q->kmax)
        q->kmax = k;
    return 0;
}

/* The (F, 3) triangles, or NULL with *nf = -1 to hand off (mixed with polygons). */
static int64_t *triangulate(polys *q, int64_t *nf)
{
    int64_t nt = (int64_t)(q->tri.len / 24), nq = (int64_t)(q->quad.len / 32);
    int64_t np_ = 0, k = q->kmax;
    if (q->poly.len) {
        if (q->kmin != q->kmax) {
            *nf = -1;
            return NULL;
        }
        np_ = (int64_t)(q->poly.len / (8 * (size_t)k));
    }
    *nf = nt + 2 * nq + np_ * (k - 2);
    /* the triangles' list grows into the result (a large realloc moves pages, not bytes) */
    int64_t *out = realloc(q->tri.data, (size_t)*nf * 24 + 1), *o = out;
    if (!out)
        return NULL;
    q->tri.data = NULL;
    q->tri.len = q->tri.cap = 0;
    o += 3 * nt;
    const int64_t *qd = (const int64_t *)q->quad.data;
    for (int64_t i = 0; i < nq; i++, o += 3)
        o[0] = qd[4 * i], o[1] = qd[4 * i + 1], o[2] = qd[4 * i + 2];
    for (int64_t i = 0; i < nq; i++, o += 3)
        o[0] = qd[4 * i + 2], o[1] = qd[4 * i + 3], o[2] = qd[4 * i];
    const int64_t *pd = (const int64_t *)q->poly.data;
    for (int64_t i = 0; i < np_; i++)
        for (int64_t j = 1; j + 1 < k; j++, o += 3)
            o[0] = pd[k * i], o[1] = pd[k * i + j], o[2] = pd[k * i + j + 1];
    return out;
}

static void polys_free(polys *q)
{
    grow_free(&q->tri);
    grow_free(&q->quad);
    grow_free(&q->poly);
}

/* A face line: count k then k indices in [0, nv) (then, for OFF, anything). */
static int face_record(cursor *c, polys *q, int64_t nv, int exact, int max_k)
{
    int64_t k, idx[MAX_CORNERS];
    skip_spaces(c);
    if (parse_int(c, &k, 0) < 0 || k < 3 || k > max_k)
        return 1;
    for (int64_t j = 0; j < k; j++) {
        skip_spaces(c);
        if (parse_int(c, &idx[j], 0) < 0 || idx[j] < 0 || idx[j] >= nv)
            return 1;
    }
    if (add_face(q, idx, (int)k) < 0)
        return -1;
    if (exact)
        return end_line(c) < 0 ? 1 : 0;
    skip_line(c);
    return 0;
}

static PyObject *polys_result(double *v, int64_t nv, polys *q, int status)
{
    PyObject *result = NULL;
    if (status < 0)
        PyErr_NoMemory();
    else if (status > 0) {
        result = Py_None;
        Py_INCREF(result);
    } else {
        int64_t nf;
        int64_t *faces = triangulate(q, &nf);
        if (!faces && nf < 0) {
            result = Py_None;
            Py_INCREF(result);
        } else if (!faces)
            PyErr_NoMemory();
        else {
            PyObject *va = owned_array(v, nv, 3, NPY_FLOAT64);
            v = NULL;
            PyObject *fa = owned_array(faces, nf, 3, NPY_INT64);
            if (va && fa)
                result = Py_BuildValue("(NN)", va, fa);
            else {
                Py_XDECREF(va);
                Py_XDECREF(fa);
            }
        }
    }
    free(v);
    polys_free(q);
    return result;
}

/* 0 and the OFF header's counts past the keyword, or 1. */
static int off_header(cursor *c, int64_t *nv, int64_t *nf)
{
    skip_blank_lines(c);
    if (starts(c, "COFF"))
        c->p += 4;
    else if (starts(c, "OFF"))
        c->p += 3;
    else
        return 1;
    skip_blank_lines(c);
    int64_t counts[3];
    int n = 0;
    for (;;) {
        skip_spaces(c);
        if (c->p >= c->end || is_break(*c->p))
            break;
        int64_t x;
        if (parse_int(c, &x, 0) < 0)
            return 1;
        if (n < 3)
            counts[n] = x;
        n++;
    }
    if (n < 2 || end_line(c) < 0 || counts[0] <= 0 || counts[1] <= 0)
        return 1;
    *nv = counts[0];
    *nf = counts[1];
    return 0;
}

/* The body of an OFF or an ASCII PLY read in parts on several threads: the same arrays
 * and the same verdict as one pass. Parts are whole lines (each ends just after a '\n',
 * the last at the end of the text). A first pass counts each part's records; then each
 * part, knowing the number of its first record, reads its records as one pass would: the
 * first nv vertices (into their rows of one array), then nf faces (into polygon lists of
 * its own, joined in part order). Records: for an OFF, the '\n'-lines holding anything
 * but spaces and CRs (one pass skips blank lines, and reads a record from its first
 * content to its '\n'); for an ASCII PLY, every line, whatever its break (CRLF, LF or a
 * lone CR), none blank, and nothing but white space after the faces. One part (a small
 * file, or one thread) is not counted: it is the one pass. */
typedef struct {
    const char *p, *stop;
    int64_t first, records; /* the number of its first record; how many it holds */
    polys q;
    int status;
} body_part;

typedef struct {
    int ply; /* 1: an ASCII PLY's rules, 0: an OFF's */
    int64_t nv, nf;
    double *v, *e;
    int props, col[3], single[3];
    const unsigned char *extra;
    Py_ssize_t ne;
    body_part *parts;
} body;

/* PLY: the lines of [p, stop) (CRLF one break). */
static int64_t count_lines(const char *p, const char *stop)
{
    int64_t n = 0;
    for (const char *q = p; q < stop && (q = memchr(q, '\n', (size_t)(stop - q))); q++)
        n++;
    if (memchr(p, '\r', (size_t)(stop - p))) /* lone CRs end lines too */
        for (const char *q = p; q < stop; q++)
            n += *q == '\r' && (q + 1 >= stop || q[1] != '\n');
    return n + (stop > p && !is_break(stop[-1])); /* a last line without a break */
}

/* OFF: the '\n'-lines of [p, stop) with something but spaces and CRs. */
static int64_t count_records(const char *p, const char *stop)
{
    int64_t n = 0;
    for (const char *line = p; line < stop;) {
        const char *nl = memchr(line, '\n', (size_t)(stop - line)), *e = nl ? nl : stop, *q = line;
        while (q < e && (is_space(*q) || *q == '\r'))
            q++;
        n += q < e;
        line = nl ? nl + 1 : stop;
    }
    return n;
}

/* The records of every part but the last (whose count numbers none). */
static void count_part(void *ctx, int k, int count)
{
    body *b = ctx;
    body_part *part = b->parts + k;
    if (k < count - 1)
        part->records = b->ply ? count_lines(part->p, part->stop) : count_records(part->p, part->stop);
}

/* One PLY vertex line into row i: 0, or 1 to hand off. */
static int ply_vertex(body *b, cursor *c, int64_t i)
{
    for (int k = 0; k < b->props; k++) {
        double d;
        skip_spaces(c);
        if (parse_double(c, &d) < 0)
            return 1;
        for (int a = 0; a < 3; a++)
            if (b->col[a] == k)
                b->v[3 * i + a] = b->single[a] ? (double)(float)d : d;
        for (Py_ssize_t a = 0; a < b->ne; a++)
            if (b->extra[a] == k)
                b->e[b->ne * i + a] = d;
    }
    return end_line(c) < 0 ? 1 : 0;
}

/* One OFF vertex record into its row (from its first content: x y z, the rest of its
 * '\n'-line ignored): 0, or 1 to hand off. */
static int off_vertex(cursor *c, double *row)
{
    for (int j = 0; j < 3; j++) {
        skip_spaces(c);
        if (parse_double(c, &row[j]) < 0)
            return 1;
    }
    skip_line(c);
    return 0;
}

/* The records of one part from record part->first on; ``last``: the part ends the text,
 * so running out of records there hands off, as one pass does. */
static int read_part(body *b, body_part *part, int last, polys *q)
{
    cursor c = {part->p, part->stop};
    int64_t i = part->first, nv = b->nv, all = b->nv + b->nf;
    double *v = b->v;
    int status = 0;
    if (!b->ply) { /* OFF: blank lines skipped, anything after the faces left unread */
        for (; i < nv && !status; i++) {
            skip_blank_lines(&c);
            if (c.p >= c.end)
                return last;
            status = off_vertex(&c, v + 3 * i);
        }
        for (; i < all && !status; i++) {
            skip_blank_lines(&c);
            if (c.p >= c.end)
                return last;
            status = face_record(&c, q, nv, 0, MAX_CORNERS);
        }
        return status;
    }
    for (; i < all && !status; i++) {
        if (c.p >= c.end)
            return last;
        status = i < nv ? ply_vertex(b, &c, i) : face_record(&c, q, nv, 1, 4);
    }
    while (!status && c.p < c.end) { /* trimesh reads every line left as numbers */
        char ch = *c.p++;
        if (!is_space(ch) && !is_break(ch))
            status = 1;
    }
    return status;
}

static void read_part_run(void *ctx, int k, int count)
{
    body *b = ctx;
    polys q = b->parts[k].q; /* (on this thread's stack while it grows) */
    b->parts[k].status = read_part(b, b->parts + k, k == count - 1, &q);
    b->parts[k].q = q;
}

/* Each part's polygon lists onto parts[0]'s, in order: 0, or -1 out of memory. */
static int join_polys(body_part *parts, int n)
{
    polys *q = &parts[0].q;
    for (int k = 1; k < n; k++) {
        polys *r = &parts[k].q;
        grow *to[3] = {&q->tri, &q->quad, &q->poly}, *from[3] = {&r->tri, &r->quad, &r->poly};
        for (int g = 0; g < 3; g++) {
            if (!from[g]->len)
                continue;
            if (grow_room(to[g], from[g]->len) < 0)
                return -1;
            memcpy(to[g]->data + to[g]->len, from[g]->data, from[g]->len);
            to[g]->len += from[g]->len;
        }
        q->kmin = r->kmin < q->kmin ? r->kmin : q->kmin;
        q->kmax = r->kmax > q->kmax ? r->kmax : q->kmax;
    }
    return 0;
}

/* The body [from, end) into b->v (and b->e) and *q, on ``threads`` threads: 0, 1 (hand
 * off) or -1 (out of memory), as one pass would say but for which of two failures. */
static int read_body(body *b, const char *from, const char *end, int threads, polys *q)
{
    int most = pieces_for(end - from, MIN_PART, threads);
    body_part *parts = calloc((size_t)most, sizeof *parts);
    if (!parts)
        return -1;
    int n = 0, status = 0;
    for (const char *p = from; n == 0 || (p < end && n < most); p = parts[n++].stop)
        parts[n] = (body_part){p, next_cut(p, end, most - n), 0, 0, {{0}, {0}, {0}, MAX_CORNERS + 1, 0}, 1};
    b->parts = parts;
    if (n > 1)
        in_pieces(n, threads, count_part, b);
    for (int k = 1; k < n; k++)
        parts[k].first = parts[k - 1].first + parts[k - 1].records;
    in_pieces(n, threads, read_part_run, b);
    for (int k = 0; k < n && !status; k++)
        status = parts[k].status; /* the first failure in file order */
    if (!status)
        status = join_polys(parts, n);
    for (int k = 1; k < n; k++)
        polys_free(&parts[k].q);
    *q = parts[0].q;
    free(parts);
    return status;
}

static PyObject *read_off(PyObject *self, PyObject *args)
{
    Py_buffer buf;
    int threads = 1;
    if (!PyArg_ParseTuple(args, "y*|i", &buf, &threads))
        return NULL;
    const char *text = buf.buf;
    cursor c = {text, text + buf.len};
    int64_t nv = 0, nf = 0;
    double *v = NULL;
    polys q = {{0}, {0}, {0}, MAX_CORNERS + 1, 0};
    int status = 1;
    Py_BEGIN_ALLOW_THREADS
    if (plain_text(text, buf.len) && !memchr(text, '#', (size_t)buf.len) && !off_header(&c, &nv, &nf) &&
        nv <= (c.end - c.p) / 6 + 1 && nf <= (c.end - c.p) / 8 + 1) {
        v = malloc((size_t)nv * 24);
        status = v ? 0 : -1;
        if (!status) {
            body b = {0, nv, nf, v, NULL, 0, {0}, {0}, NULL, 0, NULL};
            status = read_body(&b, c.p, c.end, threads, &q);
        }
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&buf);
    return polys_result(v, nv, &q, status);
}

/* The body of an ASCII PLY: nv vertex lines of `props` numbers (x, y, z at columns
 * xyz[0..2], rounded to float32 where single[k]), then nf lines `k i0 .. ik-1`, k 3 or 4.
 * `extra` (bytes, optional): more columns to keep, as parsed, in an (nv, len) float64
 * array returned third. */
static PyObject *read_ply_ascii(PyObject *self, PyObject *args)
{
    Py_buffer buf;
    Py_ssize_t offset, ne = 0;
    long long nv, nf;
    int props, x, y, z, sx, sy, sz, threads = 1;
    const unsigned char *extra = NULL;
    if (!PyArg_ParseTuple(args, "y*nLLiiiiiii|y#i", &buf, &offset, &nv, &nf, &props, &x, &y, &z, &sx, &sy, &sz,
                          &extra, &ne, &threads))
        return NULL;
    const char *text = buf.buf;
    int col[3] = {x, y, z}, single[3] = {sx, sy, sz};
    double *v = NULL, *e = NULL;
    polys q = {{0}, {0}, {0}, MAX_CORNERS + 1, 0};
    int status = 1;
    int bad_extra = ne > 8;
    for (Py_ssize_t j = 0; j < ne && !bad_extra; j++)
        bad_extra = extra[j] >= props;
    if (offset < 0 || offset > buf.len || nv <= 0 || nf <= 0 || props < 3 || bad_extra) {
        PyBuffer_Release(&buf);
        Py_RETURN_NONE;
    }
    cursor c = {text + offset, text + buf.len};
    Py_BEGIN_ALLOW_THREADS
    if (plain_text(c.p, c.end - c.p) && nv <= (c.end - c.p) / 6 + 1 && nf <= (c.end - c.p) / 8 + 1) {
        v = malloc((size_t)nv * 24);
        e = ne ? malloc((size_t)nv * (size_t)ne * 8) : NULL;
        status = v && (e || !ne) ? 0 : -1;
        if (!status) {
            body b = {1, nv, nf, v, e, props, {col[0], col[1], col[2]}, {single[0], single[1], single[2]}, extra, ne,
                      NULL};
            status = read_body(&b, c.p, c.end, threads, &q);
        }
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&buf);
    PyObject *result = polys_result(v, nv, &q, status);
    if (!ne || !result || result == Py_None) {
        free(e);
        return result;
    }
    PyObject *ea = owned_array(e, nv, ne, NPY_FLOAT64);
    if (!ea) {
        Py_DECREF(result);
        return NULL;
    }
    PyObject *both = Py_BuildValue("(OON)", PyTuple_GET_ITEM(result, 0), PyTuple_GET_ITEM(result, 1), ea);
    Py_DECREF(result);
    return both;
}

/* ---- ASCII STL ---- */

static int starts_nocase(const cursor *c, const char *word)
{
    size_t n = strlen(word);
    if ((size_t)(c->end - c->p) < n)
        return 0;
    for (size_t i = 0; i < n; i++) {
        char ch = c->p[i];
        if (ch >= 'A' && ch <= 'Z')
            ch += 'a' - 'A';
        if (ch != word[i])
            return 0;
    }
    return 1;
}

static int contains_nocase(const char *p, const char *end, const char *word)
{
    cursor c = {p, end};
    for (; c.p < c.end; c.p++)
        if (starts_nocase(&c, word))
            return 1;
    return 0;
}

/* The rest of a keyword line, which must be plain text (not_plain) without a word trimesh
 * searches for. */
static int plain_line_rest(cursor *c)
{
    const char *e = memchr(c->p, '\n', (size_t)(c->end - c->p));
    e = e ? e : c->end;
    unsigned char maybe = 0, bad = 0; /* maybe: a 'v' or 's' at all, the search is needed only then */
    for (const unsigned char *q = (const unsigned char *)c->p; q < (const unsigned char *)e; q++) {
        maybe |= (*q | 0x20) == 'v' || (*q | 0x20) == 's';
        bad |= not_plain(*q);
    }
    if (bad || (maybe && (contains_nocase(c->p, e, "vertex") || contains_nocase(c->p, e, "solid"))))
        return -1;
    c->p = e < c->end ? e + 1 : e;
    return 0;
}

/* Exactly three numbers, then the end of the line (moving past its break), as numbers()
 * then end_line() take them: 0 with the numbers in xyz (room for 3), else -1. */
static int vertex_numbers(cursor *c, double *xyz)
{
    for (int k = 0; k < 3; k++) {
        skip_spaces(c);
        if (c->p >= c->end || is_break(*c->p) || parse_double(c, &xyz[k]) < 0)
            return -1;
    }
    return end_line(c);
}

/* One stretch of an ASCII STL body, from a line start to `stop` (just after a line break,
 * or the end): its vertices, and 0 (endsolid, with no other solid after it in the file),
 * 1 (hand the file to trimesh), 2 (reached `stop` first) or -1 (no memory). The whole file
 * must be plain text (not_plain): the grammar admits only plain bytes on the lines it
 * reads but for the rest of keyword lines, which plain_line_rest checks, and the bytes
 * after endsolid, checked here for this stretch and by stl_join for the stretches after. */
typedef struct {
    const char *p, *stop, *file_end;
    grow v;
    int status;
} stl_part;

static int stl_body(stl_part *s)
{
    cursor c = {s->p, s->stop};
    for (;;) {
        skip_blank_lines(&c);
        if (c.p >= c.end)
            return 2;
        char first = *c.p | 0x20; /* lower case for letters: which keyword to test */
        if (first == 'v' && starts_nocase(&c, "vertex")) {
            c.p += 6;
            if (!at_token_end(&c))
                return 1;
            if (grow_room(&s->v, 3 * sizeof(double)) < 0)
                return -1;
            if (vertex_numbers(&c, (double *)(s->v.data + s->v.len)) < 0)
                return 1;
            s->v.len += 3 * sizeof(double);
        } else if (first == 'e' && starts_nocase(&c, "endsolid")) {
            c.p += 8; /* another solid after it: another geometry */
            return !plain_text(c.p, c.end - c.p) || contains_nocase(c.p, s->file_end, "solid") ? 1 : 0;
        } else if ((first == 'f' && starts_nocase(&c, "facet")) || (first == 'o' && starts_nocase(&c, "outer")) ||
                   (first == 'e' && (starts_nocase(&c, "endloop") || starts_nocase(&c, "endfacet")))) {
            if (plain_line_rest(&c) < 0)
                return 1;
        } else {
            return 1;
        }
    }
}

/* part k of parts (count: how many there are) */
static void stl_part_run(void *parts, int k, int count)
{
    stl_part *s = (stl_part *)parts + k;
    (void)count;
    s->status = stl_body(s);
}

/* The parts in file order decide: the first to end at endsolid ends the file, a part
 * that reached its stop hands on to the next; the vertices of the parts read are joined
 * into parts[0]. Returns the file's status as stl_body words it. */
static int stl_join(stl_part *parts, int n)
{
    for (int k = 0; k < n; k++) {
        if (parts[k].status == 1 || parts[k].status == -1)
            return parts[k].status;
        if (k > 0) {
            if (grow_room(&parts[0].v, parts[k].v.len) < 0)
                return -1;
            memcpy(parts[0].v.data + parts[0].v.len, parts[k].v.data, parts[k].v.len);
            parts[0].v.len += parts[k].v.len;
        }
        if (parts[k].status == 0) {
            for (int j = k + 1; j < n; j++)
                if (!plain_text(parts[j].p, parts[j].stop - parts[j].p))
                    return 1; /* as when the whole file is checked first */
            return 0;
        }
    }
    return 1; /* no endsolid */
}

static PyObject *read_stl_ascii(PyObject *self, PyObject *args)
{
    Py_buffer buf;
    int threads = 1;
    if (!PyArg_ParseTuple(args, "y*|i", &buf, &threads))
        return NULL;
    const char *text = buf.buf, *end = text + buf.len;
    cursor c = {text, end};
    int most = pieces_for(buf.len, MIN_PART, threads);
    stl_part *parts = calloc((size_t)most, sizeof *parts);
    if (!parts) {
        PyBuffer_Release(&buf);
        return PyErr_NoMemory();
    }
    int n = 0, status = 1;
    Py_BEGIN_ALLOW_THREADS
    skip_blank_lines(&c);
    if (starts_nocase(&c, "solid")) {
        c.p += 5;
        if (plain_line_rest(&c) == 0) {
            for (const char *p = c.p; n == 0 || (p < end && n < most); p = parts[n++].stop)
                parts[n] = (stl_part){p, next_cut(p, end, most - n), end, {0}, 1};
            in_pieces(n, threads, stl_part_run, parts);
            status = stl_join(parts, n);
        }
    }
    Py_END_ALLOW_THREADS
    PyBuffer_Release(&buf);
    for (int k = 1; k < n; k++)
        grow_free(&parts[k].v);
    grow v = parts[0].v;
    free(parts);
    size_t nv = v.len / 24;
    if (status < 0) {
        grow_free(&v);
        return PyErr_NoMemory();
    }
    if (status || nv < 3 || nv % 3) {
        grow_free(&v);
        Py_RETURN_NONE;
    }
    return owned_array(v.data, (npy_intp)nv, 3, NPY_FLOAT64);
}

static PyMethodDef methods[] = {
    {"read_obj", read_obj, METH_VARARGS,
     "read_obj(buffer, attributes=False, threads=1) -> (vertices, faces, group face counts) or None; with attributes: "
     "(vertices, faces or corner keys, group face counts, group ref forms, vt, vn)"},
    {"read_off", read_off, METH_VARARGS, "read_off(buffer, threads=1) -> (vertices, faces) or None"},
    {"read_ply_ascii", read_ply_ascii, METH_VARARGS,
     "read_ply_ascii(buffer, offset, nv, nf, props, x, y, z, x32, y32, z32, extra=b'', threads=1) -> (vertices, "
     "faces[, extra columns]) or None"},
    {"read_stl_ascii", read_stl_ascii, METH_VARARGS, "read_stl_ascii(buffer, threads=1) -> vertices (3F, 3) or None"},
    {NULL, NULL, 0, NULL},
};

static struct PyModuleDef module = {PyModuleDef_HEAD_INIT, "_creaders", "Compiled text mesh readers.", -1, methods};

PyMODINIT_FUNC PyInit__creaders(void)
{
    import_array();
    return PyModule_Create(&module);
}
