"""No two modules of the package import each other, directly or through others (function-level
imports count): a circle is how two modules come to reach for each other's private helpers."""

import grimp


def circles(package: str = "swarmbox") -> list[tuple[str, str]]:
    graph = grimp.build_graph(package, cache_dir=None)
    found = set()
    for importer in graph.modules:
        for imported in graph.find_modules_directly_imported_by(importer):
            if graph.find_shortest_chain(importer=imported, imported=importer):
                found.add(tuple(sorted((importer, imported))))
    return sorted(found)


def test_the_package_has_no_import_circle():
    assert circles() == []


def test_a_circle_is_found(tmp_path, monkeypatch):
    pkg = tmp_path / "circled"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from circled import b\n")
    (pkg / "b.py").write_text("def f():\n    from circled import c\n")
    (pkg / "c.py").write_text("import circled.a\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    # a -> b -> (inside a function) c -> a: every edge of the loop is on a circle
    assert circles("circled") == [("circled.a", "circled.b"), ("circled.a", "circled.c"),
                                  ("circled.b", "circled.c")]
