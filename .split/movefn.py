"""movefn.py SRC DST 'doc' name1 name2 ... : move top-level defs to DST, import them back into SRC."""
import ast, re, sys
src_path, dst_path, doc, *names = sys.argv[1:]
src = open(src_path).read()
lines = src.split("\n")
tree = ast.parse(src)
rng = {}
for n in tree.body:
    if isinstance(n, (ast.FunctionDef, ast.ClassDef)) and n.name in names:
        start = min([d.lineno for d in n.decorator_list] + [n.lineno])
        while lines[start - 2].strip().startswith("#"):
            start -= 1
        rng[n.name] = (start, n.end_lineno)
missing = set(names) - set(rng)
assert not missing, missing
imp_nodes = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
imports = "\n".join(lines[imp_nodes[0].lineno - 1: imp_nodes[-1].end_lineno]) + "\n"
drop = set()
body = []
for nm in names:
    s, e = rng[nm]
    drop.update(range(s, e + 1))
    body.append("\n".join(lines[s - 1:e]))
open(dst_path, "w").write(f'"""{doc}\n"""\n\n' + imports + "\n\n" + "\n\n\n".join(body) + "\n")
keep = [l for i, l in enumerate(lines, 1) if i not in drop]
out = "\n".join(keep)
out = re.sub(r"\n{4,}", "\n\n\n", out)
mod = dst_path[:-3].replace("/", ".")
mod = "trn_env." + mod
imp = f"from {mod} import (  # noqa: F401\n" + "".join(f"    {n},\n" for n in names) + ")\n"
out = out.replace(imports, imports + imp, 1)
open(src_path, "w").write(out)
