"""The tempokey package as installed by `pip install client/python` (tests/python/
install_package.py): where it is imported from, the stubs it was built with, its metadata and
documentation, and the former module name. The client's behaviour against a real server is
test_python_client.py, run with the same installed package.

Environment (tests/python/CMakeLists.txt): TEMPOKEY_VENV the virtual environment,
TEMPOKEY_BUILD_STUBS_DIR the stubs the C++ build generated from the same protos,
TEMPOKEY_VERSION the project's version, TEMPOKEY_CLIENT_DIR client/python.
"""

import filecmp
import importlib
import inspect
import os
import re
import sys
import unittest
import warnings
from pathlib import Path

import tempokey
import tempokey.v1


def env_path(name):
    value = os.environ.get(name)
    if not value:
        raise unittest.SkipTest("%s is not set; run through ctest -L python" % name)
    return value


VENV = Path(env_path("TEMPOKEY_VENV")).resolve()
BUILD_STUBS = Path(env_path("TEMPOKEY_BUILD_STUBS_DIR")) / "tempokey" / "v1"
VERSION = env_path("TEMPOKEY_VERSION")
CLIENT_DIR = Path(env_path("TEMPOKEY_CLIENT_DIR")).resolve()
MODULES = ("tempokey.bvh", "tempokey.client", "tempokey.clips", "tempokey.errors",
           "tempokey.formats", "tempokey.pipelines")


class InstalledPackageTest(unittest.TestCase):

    def test_package_comes_from_the_virtual_environment_not_the_source_tree(self):
        location = Path(tempokey.__file__).resolve()

        self.assertEqual(Path(sys.prefix).resolve(), VENV)
        self.assertTrue(location.is_relative_to(VENV), location)
        self.assertFalse(location.is_relative_to(CLIENT_DIR), location)

    def test_installed_stubs_are_the_builds_stubs(self):
        installed = Path(tempokey.v1.__file__).parent
        names = sorted(p.name for p in BUILD_STUBS.glob("*_pb2*.py"))

        self.assertEqual(sorted(p.name for p in installed.glob("*_pb2*.py")), names)
        self.assertEqual(len(names), 6, "three protos, messages and services")
        for name in names:
            with self.subTest(stub=name):
                self.assertTrue(filecmp.cmp(installed / name, BUILD_STUBS / name, shallow=False),
                                "%s differs from the build's" % name)

    def test_metadata_carries_the_projects_version_and_debian_dependencies(self):
        from importlib import metadata

        requirements = metadata.requires("tempokey")
        names = sorted(re.match(r"[A-Za-z0-9_.-]+", r).group(0) for r in requirements)

        self.assertEqual(tempokey.__version__, VERSION)
        self.assertEqual(names, ["grpcio", "protobuf"])
        self.assertTrue((Path(tempokey.__file__).parent / "py.typed").exists(),
                        "type hints are declared to type checkers (PEP 561)")

    def test_every_public_name_is_documented_and_every_function_typed(self):
        for module_name in MODULES:
            module = importlib.import_module(module_name)
            self.assertTrue(module.__doc__, module_name)
            for name in module.__all__:
                item = getattr(module, name)
                if not (inspect.isfunction(item) or inspect.isclass(item)):
                    continue
                with self.subTest(name="%s.%s" % (module_name, name)):
                    self.assertTrue(inspect.getdoc(item), "no docstring")
                    if inspect.isfunction(item):
                        signature = inspect.signature(item)
                        self.assertIsNot(signature.return_annotation, inspect.Signature.empty)
                        for parameter in signature.parameters.values():
                            self.assertIsNot(parameter.annotation, inspect.Parameter.empty,
                                             parameter.name)

    def test_package_api_lists_only_names_it_has(self):
        missing = [name for name in tempokey.__all__ if not hasattr(tempokey, name)]

        self.assertEqual(missing, [])

    def test_former_module_name_still_imports_with_a_deprecation_warning(self):
        sys.modules.pop("tempokey_client", None)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            import tempokey_client

        self.assertIs(tempokey_client.connect, tempokey.connect)
        self.assertIs(tempokey_client.reduce_operation, tempokey.reduce_operation)
        self.assertEqual([w.category for w in caught], [DeprecationWarning])
        self.assertIn("import tempokey", str(caught[0].message))


if __name__ == "__main__":
    unittest.main()
