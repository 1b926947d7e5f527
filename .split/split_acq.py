import ast, re, sys
src_path = "navigators/acquisition_tracking/navigator.py"
src = open(src_path).read()
lines = src.split("\n")
tree = ast.parse(src)
cls = [n for n in tree.body if isinstance(n, ast.ClassDef) and n.name == "AcqTrackNavigator"][0]
meth = {}
for n in cls.body:
    if isinstance(n, ast.FunctionDef):
        start = min([d.lineno for d in n.decorator_list] + [n.lineno])
        meth[n.name] = (start, n.end_lineno)
def grab(name):
    s, e = meth[name]
    return "\n".join(lines[s-1:e])
groups = {
 "intake": ["_ingest", "_samples", "_add_sample", "_return_height", "_beam_arrays", "_air_vector"],
 "centroid_filter": ["_radii", "_offsets", "_corrected", "_aided_speed", "_aided_track", "_gnss_epoch",
                     "_propagate_cov", "_aid_arrays", "_set_centroid_cov", "_ne_output_cov", "_ne_growth",
                     "_ne_change", "_fold_references", "_arrays"],
 "acquire_step": ["_predicted_snr", "_acquire"],
 "tracking_step": ["_track_grid", "_track", "_centroid_index", "_loop_sigma", "_out_of_lock"],
}
moved = {m for g in groups.values() for m in g}
out = {}
for g, names in groups.items():
    out[g] = "\n\n".join(grab(n) for n in names)
# remaining navigator: remove moved methods' line ranges
drop = set()
for m in moved:
    s, e = meth[m]
    drop.update(range(s, e + 1))
    # drop blank line after
keep = [l for i, l in enumerate(lines, 1) if i not in drop]
nav = "\n".join(keep)
nav = re.sub(r"\n{3,}(    [#@d])", r"\n\n\1", nav)
for g in groups:
    open(f".split/{g}.body", "w").write(out[g])
open(".split/nav.body", "w").write(nav)
