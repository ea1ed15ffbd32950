/* af_load: a model from its files, PATH.json and the .bin its header names beside it. (The
 * WebAssembly build leaves this file out: a page hands af_load_memory the bytes it fetched.) */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "af_internal.h"

/* The whole file at path, NUL-terminated, its length in *length; NULL where it cannot be read. */
static char *read_file(const char *path, long *length) {
    FILE *f = fopen(path, "rb");
    char *data;
    long size;
    if (!f) return NULL;
    if (fseek(f, 0, SEEK_END) != 0 || (size = ftell(f)) < 0 || fseek(f, 0, SEEK_SET) != 0) {
        fclose(f);
        return NULL;
    }
    data = (char *)malloc((size_t)size + 1);
    if (data && fread(data, 1, (size_t)size, f) != (size_t)size) {
        free(data);
        data = NULL;
    }
    fclose(f);
    if (data) data[size] = '\0';
    *length = size;
    return data;
}

af_model *af_load(const char *path, const char *angle, char *error, size_t error_size) {
    char name[4096], bin_name[4096], text[1024];
    char *json, *bin = NULL;
    const char *slash, *back;
    long json_size = 0, bin_size = 0;
    int folder;
    af_model *m;
    if (error && error_size) error[0] = '\0';
    if (!path) {
        af_say(error, error_size, "path: NULL");
        return NULL;
    }
    if (strlen(path) > sizeof name - 16) {
        af_say(error, error_size, "path: longer than %d characters", (int)sizeof name - 16);
        return NULL;
    }
    snprintf(name, sizeof name, "%s.json", path);
    if (!(json = read_file(name, &json_size))) {
        af_say(error, error_size, "path: cannot read %s", name);
        return NULL;
    }
    if (!af_complete_json(json)) {
        af_say(error, error_size, "%s: not complete JSON (a truncated or binary file?)", name);
        free(json);
        return NULL;
    }
    slash = strrchr(path, '/');
    back = strrchr(path, '\\');
    if (back && (!slash || back > slash)) slash = back;
    folder = slash ? (int)(slash - path + 1) : 0;
    if (af_string_value(af_top_value(json, "bin"), text, sizeof text)) {
        snprintf(bin_name, sizeof bin_name, "%.*s%s", folder, path, text);
        if (!(bin = read_file(bin_name, &bin_size))) {
            af_say(error, error_size, "path: %s names its arrays' file %s, and it cannot be read",
                   name, bin_name);
            free(json);
            return NULL;
        }
    }
    m = af_load_named(json, (size_t)json_size, bin, (size_t)bin_size, angle, name, error,
                      error_size);
    free(json);
    free(bin);
    return m;
}
