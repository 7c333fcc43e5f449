"""Source rules for the GPU, checked on any machine (CI has no GPU).

Taichi keeps a value made at kernel scope and read inside a parallel loop in a global buffer
aligned for scalars; on CUDA a float64 vector read from there faults with a misaligned
address (seen on an H100: every kernel that built its box vector at kernel scope failed).
So no kernel or Taichi function may build a vector at its top level and read it in a later
top-level loop: it must be built inside the loop (see circles/geometry.py). Functions that
are only ever called inside a loop are exempt: their top level is a loop body.
"""

import ast
import pathlib

PACKAGE = pathlib.Path(__file__).resolve().parents[1] / "circles"
VECTOR_MAKERS = {"Vector", "Matrix", "vec2", "vec3", "vec4", "ivec2", "ivec3", "ivec4"}


def taichi_decorator(node):
    """"kernel", "func" or None."""
    for dec in node.decorator_list:
        name = dec.attr if isinstance(dec, ast.Attribute) else getattr(dec, "id", "")
        if name in ("kernel", "func"):
            return name
    return None


def makes_vector(value):
    if isinstance(value, ast.Call):
        f = value.func
        return (f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", "")) in VECTOR_MAKERS
    return False


def is_static(expr):
    """Whether a loop runs over ti.static(...): unrolled when compiled, so not a loop of its own."""
    return isinstance(expr, ast.Call) and getattr(expr.func, "attr", None) == "static"


def called_only_in_loops(trees):
    """Names of the functions whose every call in `trees` stands inside a for loop (not one over
    ti.static, which is unrolled): their top level runs inside a loop body, not at kernel scope."""
    inside, outside = set(), set()

    def visit(node, in_loop):
        if isinstance(node, ast.Call):
            f = node.func
            name = f.attr if isinstance(f, ast.Attribute) else getattr(f, "id", None)
            (inside if in_loop else outside).add(name)
        for child in ast.iter_child_nodes(node):
            visit(child, in_loop or (isinstance(node, ast.For) and not is_static(node.iter)))

    for tree in trees:
        visit(tree, False)
    return inside - outside


def kernel_scope_vectors_read_in_loops(source, filename, loop_bodies=frozenset()):
    """(file, line, name) of each vector built at the top level of a kernel or Taichi function
    (other than the functions in `loop_bodies`) and read by a later top-level for loop of it."""
    found = []
    for node in ast.walk(ast.parse(source, filename)):
        kind = taichi_decorator(node) if isinstance(node, ast.FunctionDef) else None
        if kind is None or (kind == "func" and node.name in loop_bodies):
            continue  # a kernel's top level is kernel scope wherever Python calls it from
        made = {}
        for stmt in node.body:
            if isinstance(stmt, ast.Assign) and makes_vector(stmt.value):
                for target in stmt.targets:
                    if isinstance(target, ast.Name):
                        made[target.id] = stmt.lineno
            elif isinstance(stmt, ast.For):
                used = {n.id for n in ast.walk(stmt) if isinstance(n, ast.Name)}
                found += [(filename, line, name) for name, line in made.items() if name in used]
    return found


def test_no_kernel_scope_vector_is_read_in_a_loop():
    sources = {path.name: path.read_text() for path in sorted(PACKAGE.glob("*.py"))}
    loop_bodies = called_only_in_loops([ast.parse(text) for text in sources.values()])
    found = []
    for name, text in sources.items():
        found += kernel_scope_vectors_read_in_loops(text, name, loop_bodies)
    assert not found, ("vectors built at kernel scope and read in a parallel loop (build them inside "
                       f"the loop): {found}")


def test_the_rule_finds_the_pattern():
    bad = '''
@ti.kernel
def k(a: ti.types.ndarray(), w: ti.f64, h: ti.f64):
    box = ti.Vector([w, h], dt=ti.f64)
    for i in range(a.shape[0]):
        a[i] = a[i] * box
'''
    good = bad.replace("    box = ti.Vector([w, h], dt=ti.f64)\n    for i in range(a.shape[0]):\n",
                       "    for i in range(a.shape[0]):\n        box = ti.Vector([w, h], dt=ti.f64)\n")
    assert kernel_scope_vectors_read_in_loops(bad, "bad.py") == [("bad.py", 4, "box")]
    assert kernel_scope_vectors_read_in_loops(good, "good.py") == []
