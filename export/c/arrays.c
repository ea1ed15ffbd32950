/* Reading an arrays file's header and arrays: PATH.json, a JSON header whose "arrays" table
 * gives each array's dtype, shape and byte offset in PATH.bin (raw little-endian, C order).
 * Every array is checked against the .bin's length and, in float64, for a non-finite entry. */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "af_internal.h"

void af_say(char *error, size_t size, const char *fmt, ...) {
    va_list args;
    if (!error || !size) return;
    va_start(args, fmt);
    vsnprintf(error, size, fmt, args);
    va_end(args);
}

static int blank(char c) { return c == ' ' || c == '\n' || c == '\r' || c == '\t'; }

/* At p, an opening quote: the text after `"key":` where the string there is that key, else
 * NULL (k: the key's length). */
static const char *after_key(const char *p, const char *key, size_t k) {
    const char *c;
    if (strncmp(p + 1, key, k) != 0 || p[k + 1] != '"') return NULL;
    for (c = p + k + 2; blank(*c); c++) continue;
    if (*c != ':') return NULL;
    for (c++; blank(*c); c++) continue;
    return c;
}

/* At p, an opening quote: its closing quote (escapes skipped), or the terminator. */
static const char *string_end(const char *p) {
    for (p++; *p && *p != '"'; p++)
        if (*p == '\\' && p[1]) p++;
    return p;
}

const char *af_value_of(const char *start, const char *key) {
    size_t k = strlen(key);
    const char *p, *v;
    for (p = start; (p = strchr(p, '"')) != NULL; p++)
        if ((v = after_key(p, key, k)) != NULL) return v;
    return NULL;
}

const char *af_top_value(const char *json, const char *key) {
    size_t k = strlen(key);
    long depth = 0;
    const char *p, *v;
    for (p = json; *p; p++) {
        if (*p == '"') {
            if (depth == 1 && (v = after_key(p, key, k)) != NULL) return v;
            if (!*(p = string_end(p))) return NULL;
        } else if (*p == '{' || *p == '[') {
            depth++;
        } else if (*p == '}' || *p == ']') {
            depth--;
        }
    }
    return NULL;
}

int af_complete_json(const char *text) {
    long depth = 0;
    const char *p;
    for (p = text; *p; p++) {
        if (*p == '"') {
            if (!*(p = string_end(p))) return 0;
        } else if (*p == '{' || *p == '[') {
            depth++;
        } else if (*p == '}' || *p == ']') {
            if (--depth < 0) return 0;
            if (depth == 0) {
                for (p++; blank(*p); p++) continue;
                return *p == '\0';
            }
        }
    }
    return 0;
}

int af_string_value(const char *v, char *out, size_t size) {
    size_t i = 0;
    if (size) out[0] = '\0';
    if (!v || *v != '"' || !size) return 0;
    for (v++; *v && *v != '"' && i + 1 < size; v++) out[i++] = *v;
    out[i] = '\0';
    return *v == '"';
}

char *af_string_list(const char *v, int *count) {
    const char *p, *end;
    char *out, *w;
    *count = 0;
    if (!v || *v != '[') return NULL;
    for (p = v + 1; blank(*p); p++) continue;
    if (!(out = (char *)malloc(strlen(v) + 1))) return NULL;
    w = out;
    while (*p == '"') {
        end = string_end(p);
        if (!*end) break;
        memcpy(w, p + 1, (size_t)(end - p - 1));
        w += end - p - 1;
        *w++ = '\0';
        ++*count;
        for (p = end + 1; blank(*p); p++) continue;
        if (*p == ',')
            for (p++; blank(*p); p++) continue;
    }
    if (*p != ']') {
        free(out);
        *count = 0;
        return NULL;
    }
    return out;
}

typedef struct { long shape[4]; int dims; long offset; char dtype[16]; } spec;

/* The spec of `key` in the arrays table; 0 if it is missing or not an array spec. */
static int array_spec(const char *table, const char *key, spec *s) {
    const char *obj = af_value_of(table, key), *end, *v;
    char *next;
    if (!obj || *obj != '{' || !(end = strchr(obj, '}'))) return 0;
    v = af_value_of(obj, "dtype");
    if (!v || v > end || !af_string_value(v, s->dtype, sizeof s->dtype)) return 0;
    v = af_value_of(obj, "offset");
    if (!v || v > end) return 0;
    s->offset = strtol(v, &next, 10);
    if (next == v) return 0;
    v = af_value_of(obj, "shape");
    if (!v || v > end || *v != '[') return 0;
    s->dims = 0;
    v++;
    while (blank(*v)) v++;
    while (*v && *v != ']') {
        if (s->dims == 4) return 0;
        s->shape[s->dims] = strtol(v, &next, 10);
        if (next == v || s->shape[s->dims] < 0) return 0;
        s->dims++;
        v = next;
        while (*v == ',' || blank(*v)) v++;
    }
    return *v == ']';
}

static void key_of(const af_file *f, const char *name, int tagged, char *key, size_t size) {
    snprintf(key, size, "%s%s", name, tagged ? f->tag : "");
}

int af_has_array(const af_file *f, const char *name, int tagged) {
    char key[96];
    spec s;
    key_of(f, name, tagged, key, sizeof key);
    return array_spec(f->table, key, &s);
}

static long width_of(const char *dtype) {
    if (!strcmp(dtype, "float64")) return 8;
    if (!strcmp(dtype, "int32")) return 4;
    if (!strcmp(dtype, "uint8")) return 1;
    return 0;
}

void *af_array(const af_file *f, const char *name, int tagged, const char *type, int dims,
               long *shape) {
    char key[96];
    spec s;
    long count = 1, width = width_of(type), i;
    if (!width) {
        af_say(f->error, f->error_size, "%s: array %s: unknown dtype %s", f->name, name, type);
        return NULL;
    }
    char *out;
    key_of(f, name, tagged, key, sizeof key);
    if (!array_spec(f->table, key, &s)) {
        af_say(f->error, f->error_size, "%s: no array %s in its arrays table", f->name, key);
        return NULL;
    }
    if (strcmp(s.dtype, type) != 0) {
        af_say(f->error, f->error_size, "%s: array %s is %s, expected %s", f->name, key,
               s.dtype, type);
        return NULL;
    }
    if (s.dims != dims) {
        af_say(f->error, f->error_size, "%s: array %s has %d dimensions, expected %d", f->name,
               key, s.dims, dims);
        return NULL;
    }
    for (i = 0; i < dims; i++) {
        if (s.shape[i] > 0 && count > 0x7fffffffL / s.shape[i]) {
            af_say(f->error, f->error_size, "%s: array %s is too large", f->name, key);
            return NULL;
        }
        count *= s.shape[i];
        shape[i] = s.shape[i];
    }
    if (s.offset < 0 || s.offset % width) {
        af_say(f->error, f->error_size, "%s: array %s starts at offset %ld, not a multiple of "
               "its %ld-byte entries", f->name, key, s.offset, width);
        return NULL;
    }
    if (s.offset > f->bin_size || count * width > f->bin_size - s.offset) {
        af_say(f->error, f->error_size, "%s: array %s (%ld bytes at offset %ld) runs past the "
               "end of the %ld-byte .bin file", f->name, key, count * width, s.offset,
               f->bin_size);
        return NULL;
    }
    out = (char *)malloc((size_t)(count * width) + 1);
    if (!out) {
        af_say(f->error, f->error_size, "%s: no memory for array %s", f->name, key);
        return NULL;
    }
    memcpy(out, f->bin + s.offset, (size_t)(count * width));
    if (width == 8)
        for (i = 0; i < count; i++)
            if (!isfinite(((double *)out)[i])) {
                af_say(f->error, f->error_size, "%s: array %s holds a non-finite number at "
                       "entry %ld", f->name, key, i);
                free(out);
                return NULL;
            }
    return out;
}
