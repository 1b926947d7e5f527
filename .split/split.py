"""split.py SRC CLASS groups.json : move methods of CLASS into mixin modules."""
import ast, json, re, sys
src_path, cls_name, spec_path = sys.argv[1:4]
spec = json.load(open(spec_path))
src = open(src_path).read()
lines = src.split("\n")
tree = ast.parse(src)
cls = [n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == cls_name][0]
meth = {}
for n in cls.body:
    if isinstance(n, ast.FunctionDef):
        start = min([d.lineno for d in n.decorator_list] + [n.lineno])
        # include directly preceding comment lines
        while lines[start - 2].strip().startswith("#"):
            start -= 1
        meth[n.name] = (start, n.end_lineno)
first_stmt = tree.body[1] if isinstance(tree.body[0], ast.Expr) else tree.body[0]
imp_lines = [n for n in tree.body if isinstance(n, (ast.Import, ast.ImportFrom))]
imports = "\n".join(lines[imp_lines[0].lineno - 1: imp_lines[-1].end_lineno]) + "\n"
drop = set()
mod_pkg = spec["package"]
bases = []
for g in spec["groups"]:
    body = "\n\n".join("\n".join(lines[meth[m][0]-1:meth[m][1]]) for m in g["methods"])
    for m in g["methods"]:
        drop.update(range(meth[m][0], meth[m][1] + 1))
    extra = g.get("imports", "")
    mod = f'"""{g["doc"]}\n"""\n\n' + imports + extra + f'\n\nclass {g["class"]}:\n    """{g["classdoc"]}"""\n\n' + body + "\n"
    open(f'{g["module"]}', "w").write(mod)
    modname = g["module"][:-3].replace("/", ".")
    bases.append((modname, g["class"]))
keep = [l for i, l in enumerate(lines, 1) if i not in drop]
out = "\n".join(keep)
out = re.sub(r"\n{3,}(    [#@d])", r"\n\n\1", out)
out = re.sub(rf"class {cls_name}(\(([^)]*)\))?:", lambda m: f"class {cls_name}({', '.join([c for _, c in bases] + ([m.group(2)] if m.group(2) else []))}):", out, count=1)
imp_add = "".join(f"from trn_env.{mn} import {c}\n" for mn, c in bases)
last_imp = lines[imp_lines[-1].end_lineno - 1]
out = out.replace(imports, imports + imp_add, 1)
open(src_path, "w").write(out)
