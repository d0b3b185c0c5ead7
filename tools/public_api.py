#!/usr/bin/env python3
"""Public surface of the tarn core (src/): declarations written `pub` and items reachable as public paths.

Usage: tools/public_api.py [REPO] [--list]   (REPO defaults to this checkout)
Declarations: in each file's non-test code (the text before its first `#[cfg(test)]`), every
`pub fn/struct/enum/const/static/type/trait/mod/use` and every `pub` field (plain `pub`, not
`pub(crate)`/`pub(super)`).
Reachable paths: walking the module tree from lib.rs, each `pub mod` whose parents are all
public, plus, in every such public module, its top-level `pub` items and each name a `pub use`
brings in (the test code left out as above)."""
import os, re, sys

args = [a for a in sys.argv[1:] if a != '--list']
repo = args[0] if args else os.path.join(os.path.dirname(os.path.abspath(__file__)), '..')
listing = '--list' in sys.argv
SRC = os.path.join(repo, 'src')

def strip(text):
    # comments and string/char literal contents out, lengths kept roughly (newlines kept)
    out = []; i = 0; n = len(text)
    while i < n:
        c = text[i]
        if text.startswith('//', i):
            j = text.find('\n', i); j = n if j < 0 else j
            i = j
        elif text.startswith('/*', i):
            depth = 0
            while i < n:
                if text.startswith('/*', i): depth += 1; i += 2
                elif text.startswith('*/', i): depth -= 1; i += 2
                else:
                    if text[i] == '\n': out.append('\n')
                    i += 1
                if depth == 0: break
        elif c == 'r' and re.match(r'r#*"', text[i:i+5]) and (i == 0 or not (text[i-1].isalnum() or text[i-1] == '_')):
            m = re.match(r'r(#*)"', text[i:]); hashes = m.group(1)
            end = text.find('"' + hashes, i + len(m.group(0)))
            out.append('""'); out.append('\n' * text.count('\n', i, end)); i = end + 1 + len(hashes)
        elif c == '"':
            j = i + 1
            while j < n and text[j] != '"':
                j += 2 if text[j] == '\\' else 1
            out.append('""'); out.append('\n' * text.count('\n', i, j)); i = j + 1
        elif c == "'":
            m = re.match(r"'(\\u\{[0-9a-fA-F]+\}|\\x[0-9a-fA-F]{2}|\\.|[^\\'])'", text[i:])
            if m: out.append("' '"); i += len(m.group(0))
            else: out.append(c); i += 1
        else:
            out.append(c); i += 1
    return ''.join(out)

def non_test(text):
    at = text.find('#[cfg(test)]')
    return text if at < 0 else text[:at]

DECL = re.compile(r'^\s*pub\s+(?:(?:const|async|unsafe|extern\s+"C")\s+)*(fn|struct|enum|const|static|type|trait|mod|use)\b', re.M)
FIELD = re.compile(r'^\s*pub\s+(?:r#)?[a-z_][A-Za-z0-9_]*\s*:(?!:)', re.M)
TUPLE_FIELD = re.compile(r'[(,]\s*pub\s+(?!\()', re.M)

decl_total = {}; field_total = 0
for top, dirs, files in os.walk(SRC):
    for f in files:
        if f.endswith('.rs'):
            p = os.path.join(top, f)
            code = non_test(strip(open(p).read()))
            for m in DECL.finditer(code):
                decl_total[m.group(1)] = decl_total.get(m.group(1), 0) + 1
            field_total += len(FIELD.findall(code)) + len(TUPLE_FIELD.findall(code))

# reachable paths
ident = r'[A-Za-z_][A-Za-z0-9_]*'
def use_leaves(tree):
    # names a use tree brings in
    tree = re.sub(r'\s+', ' ', tree).strip()
    names = []
    def walk(s):
        s = s.strip()
        # split top-level by commas
        depth = 0; parts = []; cur = ''
        for ch in s:
            if ch == '{': depth += 1
            if ch == '}': depth -= 1
            if ch == ',' and depth == 0: parts.append(cur); cur = ''
            else: cur += ch
        parts.append(cur)
        for part in parts:
            part = part.strip()
            if not part: continue
            if '{' in part:
                walk(part[part.index('{') + 1: part.rindex('}')])
            else:
                m = re.search(r'\bas\s+(' + ident + r')\s*$', part)
                if m: names.append(m.group(1))
                else: names.append(part.split('::')[-1].strip())
    walk(tree)
    return names

reach = []  # (path, kind)
def module_items(code, path, modfile_dir, public, depth_name):
    # scan top-level (depth 0) declarations of this module's code
    i = 0; depth = 0; n = len(code)
    tok = re.compile(r'\{|\}|(^|\n)\s*(pub(?:\([^)]*\))?\s+)?(?:(?:const|async|unsafe)\s+)*(fn|struct|enum|const|static|type|trait|mod|use|impl|macro_rules!)\b')
    pos = 0
    while True:
        m = tok.search(code, pos)
        if not m: break
        if m.group(0) == '{': depth += 1; pos = m.end(); continue
        if m.group(0) == '}': depth -= 1; pos = m.end(); continue
        pos = m.end()
        if depth != 0: continue
        vis = (m.group(2) or '').strip(); kind = m.group(3)
        is_pub = vis == 'pub'
        if kind == 'mod':
            mm = re.match(r'\s*(' + ident + r')\s*([;{])', code[m.end():])
            name = mm.group(1)
            if mm.group(2) == ';':
                sub = resolve(modfile_dir, name)
                subcode = non_test(strip(open(sub[0]).read())) if sub else ''
                subdir = sub[1] if sub else modfile_dir
            else:
                # inline module: body until matching brace
                start = m.end() + mm.end()
                d = 1; j = start
                while d:
                    if code[j] == '{': d += 1
                    elif code[j] == '}': d -= 1
                    j += 1
                subcode = code[start:j - 1]; subdir = os.path.join(modfile_dir, name)
                pos = j
            if public and is_pub:
                reach.append((path + '::' + name, 'mod'))
            module_items(subcode, path + '::' + name, subdir, public and is_pub, name)
        elif kind == 'use':
            end = code.find(';', m.end())
            if public and is_pub:
                for nm in use_leaves(code[m.end():end]):
                    reach.append((path + '::' + nm, 'use'))
            pos = end + 1
        elif kind in ('impl', 'macro_rules!'):
            pass
        else:
            if public and is_pub:
                mm = re.match(r'\s*(' + ident + r')', code[m.end():])
                reach.append((path + '::' + mm.group(1), kind))

def resolve(d, name):
    a = os.path.join(d, name + '.rs'); b = os.path.join(d, name, 'mod.rs')
    if os.path.exists(a): return a, os.path.join(d, name)
    if os.path.exists(b): return b, os.path.join(d, name)
    return None

module_items(non_test(strip(open(os.path.join(SRC, 'lib.rs')).read())), 'tarn', SRC, True, 'tarn')
# submodule files resolve relative to their own dir: x.rs's children live in x/, mod.rs's beside it
print('declarations written `pub` (non-test code of src/):')
for k in sorted(decl_total): print(f'  pub {k}: {decl_total[k]}')
print(f'  pub fields: {field_total}')
print(f'  total: {sum(decl_total.values()) + field_total}')
mods = [p for p, k in reach if k == 'mod']
items = [p for p, k in reach if k != 'mod']
print('reachable public paths:')
print(f'  public modules (tarn:: ...): {len(mods)}')
print(f'  items in public modules (incl. re-exported names): {len(items)}')
print(f'  total: {len(reach)}')
if listing:
    for p, k in reach: print(f'{k:6} {p}')
