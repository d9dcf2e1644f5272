"""ARCHITECTURE.md stays true: every folder and file path it names exists in the source tree.

A path is any `backticked` text that contains a slash and no spaces: folders end with "/",
files have an extension. Paths are relative to the repository root, except those that start
with "tests/" or another top-level folder, which are the same thing.
"""
import os
import re
import sys
import unittest

SOURCE_DIR = os.environ.get("TEMPOKEY_SOURCE_DIR",
                            os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))


def named_paths(text):
    paths = []
    for token in re.findall(r"`([^`\s]+)`", text):
        if "/" not in token or token.startswith(("http", "-")):
            continue
        token = token.rstrip(",.;:")
        # "core/include/tempokey/core/<subject>/" names a pattern, not a folder.
        if "<" in token or "*" in token or "…" in token:
            continue
        paths.append(token)
    return paths


class ArchitecturePageTest(unittest.TestCase):
    def setUp(self):
        with open(os.path.join(SOURCE_DIR, "ARCHITECTURE.md"), encoding="utf-8") as f:
            self.text = f.read()

    def test_names_many_paths(self):
        # Guards the parser: a page whose paths are no longer recognised would pass vacuously.
        self.assertGreater(len(named_paths(self.text)), 30)

    def test_every_named_folder_and_file_exists(self):
        missing = []
        for path in named_paths(self.text):
            full = os.path.join(SOURCE_DIR, path)
            if path.endswith("/"):
                if not os.path.isdir(full):
                    missing.append(path)
            elif not os.path.exists(full):
                missing.append(path)
        self.assertEqual(missing, [], "ARCHITECTURE.md names paths that do not exist")

    def test_readme_links_the_page(self):
        with open(os.path.join(SOURCE_DIR, "README.md"), encoding="utf-8") as f:
            self.assertTrue("ARCHITECTURE.md" in f.read(), "README.md does not link ARCHITECTURE.md")


if __name__ == "__main__":
    sys.exit(unittest.main())
