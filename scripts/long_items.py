#!/usr/bin/env python3
"""List functions longer than a limit (80 lines by default) in Rust and C++ sources.

Usage: scripts/long_items.py [--limit N] [--count] [PATH ...]
PATHs default to src/ and cpp/ (and include/). A function's length runs from the
line of its signature (`fn` in Rust; the line holding the opening parenthesis of
the parameter list in C++) to the line of its closing brace. Nested functions are
listed on their own and also count toward the function around them.

The scan is lexical: string literals, character literals and comments are blanked
first so that braces inside them do not count. It is a code-review aid, not a
parser; the file-size limit itself is checked by tests/layers.rs.
"""
import argparse
import re
import sys
from pathlib import Path

RUST_EXT = {".rs"}
CPP_EXT = {".cc", ".cpp", ".h", ".hpp"}
CONTROL = {"if", "for", "while", "switch", "catch", "return", "sizeof", "else", "do"}


def blank_rust(text: str) -> str:
    """Replace comments, strings and char literals by spaces, keeping newlines."""
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            depth, j = 1, i + 2
            while j < n and depth:
                if text.startswith("/*", j):
                    depth, j = depth + 1, j + 2
                elif text.startswith("*/", j):
                    depth, j = depth - 1, j + 2
                else:
                    j += 1
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif re.match(r'(b|br|r)#*"', text[i:i + 12]) and (i == 0 or not (text[i - 1].isalnum() or text[i - 1] == "_")):
            m = re.match(r'(b?r)(#*)"', text[i:i + 12])
            if m:  # raw string
                close = '"' + m.group(2)
                j = text.find(close, i + len(m.group(0)))
                j = n if j < 0 else j + len(close)
            else:  # byte string b"..."
                j = skip_quoted(text, i + 1, '"')
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == '"':
            j = skip_quoted(text, i, '"')
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "'":
            # A char literal ('a', '\n', '\u{1F}') or a lifetime ('a).
            m = re.match(r"'(\\u\{[0-9a-fA-F]+\}|\\.|[^\\'\n])'", text[i:i + 12])
            if m:
                out.append(" " * len(m.group(0)))
                i += len(m.group(0))
            else:
                out.append(c)
                i += 1
        else:
            out.append(c)
            i += 1
    return "".join(out)


def skip_quoted(text: str, i: int, quote: str) -> int:
    """Index just past the string literal opening at `i`."""
    j = i + 1
    while j < len(text):
        if text[j] == "\\":
            j += 2
            continue
        if text[j] == quote:
            return j + 1
        j += 1
    return j


def blank_cpp(text: str) -> str:
    out = []
    i, n = 0, len(text)
    while i < n:
        c = text[i]
        if text.startswith("//", i):
            j = text.find("\n", i)
            j = n if j < 0 else j
            out.append(" " * (j - i))
            i = j
        elif text.startswith("/*", i):
            j = text.find("*/", i + 2)
            j = n if j < 0 else j + 2
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif text.startswith('R"', i) and (i == 0 or not text[i - 1].isalnum()):
            m = re.match(r'R"([^(\s]*)\(', text[i:i + 20])
            close = ")" + (m.group(1) if m else "") + '"'
            j = text.find(close, i + 2)
            j = n if j < 0 else j + len(close)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c in "\"'":
            if c == "'" and i > 0 and text[i - 1].isalnum():
                out.append(c)  # digit separator 1'000
                i += 1
                continue
            j = skip_quoted(text, i, c)
            out.append(re.sub(r"[^\n]", " ", text[i:j]))
            i = j
        elif c == "#" and (i == 0 or text[i - 1] == "\n"):
            # Preprocessor line (with continuations): no braces count.
            j = i
            while True:
                k = text.find("\n", j)
                if k < 0:
                    k = n
                    break
                if text[k - 1] != "\\":
                    break
                j = k + 1
            out.append(re.sub(r"[^\n]", " ", text[i:k]))
            i = k
        else:
            out.append(c)
            i += 1
    return "".join(out)


def matching_brace(code: str, open_at: int) -> int:
    depth = 0
    for j in range(open_at, len(code)):
        if code[j] == "{":
            depth += 1
        elif code[j] == "}":
            depth -= 1
            if depth == 0:
                return j
    return len(code) - 1


def rust_functions(code: str):
    """(name, first line, last line) of every `fn` with a body."""
    for m in re.finditer(r"\bfn\s+([A-Za-z_][A-Za-z0-9_]*)", code):
        # The body opens at the first `{` outside parentheses/brackets/angles after
        # the signature; a `;` first means a declaration without a body.
        depth = 0
        j = m.end()
        while j < len(code):
            ch = code[j]
            if ch in "([":
                depth += 1
            elif ch in ")]":
                depth -= 1
            elif ch == ";" and depth == 0:
                j = -1
                break
            elif ch == "{" and depth == 0:
                break
            j += 1
        if j < 0 or j >= len(code):
            continue
        end = matching_brace(code, j)
        yield m.group(1), code.count("\n", 0, m.start()) + 1, code.count("\n", 0, end) + 1


def cpp_functions(code: str):
    """(name, first line, last line) of every function body at namespace or class scope."""
    # Scopes: a stack of kinds ('ns' for namespace/class/struct/extern/top, 'fn', 'other').
    stack = []
    header_start = 0
    i = 0
    while i < len(code):
        ch = code[i]
        if ch == "{":
            header = code[header_start:i]
            kind = "other"
            if all(k != "fn" for k, _ in stack):
                kind = classify_cpp_header(header)
            if kind == "fn":
                name, line = cpp_signature(code, header_start, header)
                end = matching_brace(code, i)
                yield name, line, code.count("\n", 0, end) + 1
            stack.append((kind, i))
            header_start = i + 1
        elif ch == "}":
            if stack:
                stack.pop()
            header_start = i + 1
        elif ch == ";":
            header_start = i + 1
        elif ch == ":" and re.search(r"\b(public|private|protected)\s*$", code[header_start:i]):
            header_start = i + 1
        i += 1


def classify_cpp_header(header: str) -> str:
    h = " ".join(header.split())
    if not h:
        return "other"
    if re.search(r"\b(namespace|class|struct|union|enum)\b[^()]*$", h) or h.startswith("extern"):
        return "ns"
    if re.search(r"=\s*$", h) or "=" in h.split("(")[0]:
        return "other"  # initialiser
    first = re.match(r"[A-Za-z_]\w*", h)
    if first and first.group(0) in CONTROL:
        return "other"
    if "(" in h and re.search(r"\)\s*(const|override|final|noexcept|mutable|&|&&|\s)*(->\s*[\w:<>,\s*&]+)?$", h):
        return "fn"
    # Constructor with an initialiser list: `Name(args) : a_(x), b_{y}` ends in `)` or `}`.
    if re.search(r"\)\s*:\s*[\w:]+\s*[({]", h):
        return "fn"
    return "other"


def cpp_signature(code: str, header_start: int, header: str):
    m = None
    for m in re.finditer(r"([~A-Za-z_][\w:~]*(?:operator\s*\S+?)?)\s*\(", header):
        if m.group(1) not in CONTROL:
            break
    name = m.group(1) if m else "?"
    at = header_start + (m.start() if m else len(header) - len(header.lstrip()))
    return name, code.count("\n", 0, at) + 1


def scan(path: Path, limit: int):
    text = path.read_text(encoding="utf-8", errors="replace")
    if path.suffix in RUST_EXT:
        found = rust_functions(blank_rust(text))
    else:
        found = cpp_functions(blank_cpp(text))
    for name, first, last in found:
        length = last - first + 1
        if length > limit:
            yield length, f"{path}:{first}", name


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("paths", nargs="*", default=["src", "cpp", "include"])
    parser.add_argument("--limit", type=int, default=80)
    parser.add_argument("--count", action="store_true", help="print only the number found")
    args = parser.parse_args()
    files = []
    for p in map(Path, args.paths):
        if p.is_dir():
            files += sorted(f for f in p.rglob("*") if f.suffix in RUST_EXT | CPP_EXT)
        elif p.exists():
            files.append(p)
    rows = sorted((row for f in files for row in scan(f, args.limit)), key=lambda r: (-r[0], r[1]))
    if args.count:
        print(len(rows))
    else:
        for length, where, name in rows:
            print(f"{length:5d}  {where}  {name}")
        print(f"{len(rows)} functions over {args.limit} lines", file=sys.stderr)
    return 0


if __name__ == "__main__":
    sys.exit(main())
