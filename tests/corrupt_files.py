"""Copies of a model file with one thing wrong: what tests/test_c_runtime.py and
tests/test_reduced_runtime.py hand each runtime to see it refuse with a message."""
import json
import os

import numpy as np


def corrupt(path, out, edit_header=None, edit_bin=None):
    """A copy of the model file at path as out (.json + .bin), its header dict passed through
    edit_header(header) and its bytes through edit_bin(bytes, header); returns out."""
    with open(path + ".json") as f:
        header = json.load(f)
    data = bytearray(open(path + ".bin", "rb").read())
    if edit_bin:
        data = edit_bin(data, header)
    header["bin"] = os.path.basename(out) + ".bin"
    if edit_header:
        edit_header(header)
    with open(out + ".json", "w") as f:
        json.dump(header, f)
    with open(out + ".bin", "wb") as f:
        f.write(bytes(data))
    return out


def nan_at(name):
    """edit_bin: the first entry of array `name` NaN."""
    def edit(data, header):
        offset = header["arrays"][name]["offset"]
        data[offset:offset + 8] = np.array([np.nan]).tobytes()
        return data
    return edit


def set_spec(name, key, value):
    """edit_header: array `name`'s spec entry `key` replaced by value(it)."""
    def edit(header):
        header["arrays"][name][key] = value(header["arrays"][name][key])
    return edit


def truncated_header(path, out):
    """A copy whose header keeps only its first half."""
    corrupt(path, out)
    text = open(out + ".json").read()
    with open(out + ".json", "w") as f:
        f.write(text[:len(text) // 2])
    return out


def cut_bin(data, header):
    """edit_bin: the first half of the .bin."""
    return data[:len(data) // 2]
