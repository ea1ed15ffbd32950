"""A scene file's table written back as TOML text (the standard library reads TOML but does
not write it): what `fit` and `design` write."""


def dump(table):
    """A scene file's table (as load_scene reads it, tomllib's dict) as TOML text: top-level
    values, then [material], [regions.NAME], [[boundary]] and [curves.NAME] tables; nested
    tables inline."""
    lines = [f"{k} = {_toml(v)}" for k, v in table.items() if not isinstance(v, (dict, list))
             or (isinstance(v, list) and not (v and isinstance(v[0], dict)))]
    for k, v in table.items():
        if isinstance(v, dict) and k in ("regions", "curves"):
            for name, sub in v.items():
                lines += ["", f"[{k}.{_key(name)}]"] + [f"{a} = {_toml(b)}" for a, b in
                                                        sub.items()]
        elif isinstance(v, dict):
            lines += ["", f"[{k}]"] + [f"{a} = {_toml(b)}" for a, b in v.items()]
        elif isinstance(v, list) and v and isinstance(v[0], dict):
            for entry in v:
                lines += ["", f"[[{k}]]"] + [f"{a} = {_toml(b)}" for a, b in entry.items()]
    return "\n".join(lines) + "\n"


def _key(name):
    return name if name.replace("_", "").replace("-", "").isalnum() and not name.isdigit() \
        else '"' + name + '"'


def _toml(value):
    """One TOML value: a bool, number, string, list or inline table."""
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, (int, float)):
        return repr(float(value)) if isinstance(value, float) else str(value)
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    if isinstance(value, dict):
        return "{" + ", ".join(f"{_key(k)} = {_toml(v)}" for k, v in value.items()) + "}"
    return "[" + ", ".join(_toml(v) for v in value) + "]"
