"""No module of the project imports itself back through others (issue 60).

The layers contract (``lint-imports``, pyproject.toml) keeps imports downward between packages;
this keeps them acyclic within a package too, lazy imports inside functions included: a type
that two modules share lives in a module below both.
"""

from __future__ import annotations

import pytest

pytestmark = pytest.mark.unit

PACKAGES = ("meshes", "fem", "surrogate", "studies", "run", "report", "benchmarks")


def test_no_module_imports_itself_back() -> None:
    import grimp

    graph = grimp.build_graph(*PACKAGES)
    cycles = set()
    for module in sorted(graph.modules):
        for imported in graph.find_modules_directly_imported_by(module):
            back = graph.find_shortest_chain(importer=imported, imported=module)
            if back:
                cycles.add(" -> ".join((module, *back)))
    assert not cycles, "\n".join(sorted(cycles))
