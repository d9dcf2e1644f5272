"""Checks deploy/k8s/ and deploy/k8s/batch/ against the Kubernetes API's own schema.

test_manifests.py holds the manifests to the project's reading of the rules; nothing there would
notice a misspelled field (`backoffLimitPerIndx`), a field under the wrong parent or a string
where an integer goes, which kube-apiserver rejects (or, without strict field validation, drops
silently). Here every document of every manifest is turned into JSON with python3-yaml and
checked by validate_k8s.mjs against the OpenAPI schemas of Kubernetes v1.36 compiled by the npm
package kubernetes-models (pinned in package.json and package-lock.json beside this file), with
unknown fields rejected as well (the evidence for the version and for that strictness is at the
top of validate_k8s.mjs). The check is shown to fail: copies of the real manifests with one
mistake each must be reported, by document and field path.

Run by CTest (label `deploy`) as `/usr/bin/python3 test_k8s_schema.py`; exits 77 (skipped) when
python3-yaml, node or tests/deploy/node_modules is missing (deploy/install-deps.sh installs all
three). Environment: TEMPOKEY_SOURCE_DIR (default: two levels up) and TEMPOKEY_NODE (default:
node on PATH).
"""

import copy
import json
import os
import re
import shutil
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

try:
    import yaml
except ImportError:  # reported by main() below as a skip
    yaml = None

HERE = Path(__file__).resolve().parent
SOURCE_DIR = Path(os.environ.get("TEMPOKEY_SOURCE_DIR") or HERE.parents[1])
MANIFEST_DIRS = [SOURCE_DIR / "deploy" / "k8s", SOURCE_DIR / "deploy" / "k8s" / "batch"]
VALIDATOR = HERE / "validate_k8s.mjs"
NODE_MODULES = HERE / "node_modules"
NODE = os.environ.get("TEMPOKEY_NODE") or shutil.which("node")
VALIDATE_TIMEOUT_SECONDS = 30

# Every kind the manifests hold: a document silently dropped from the check would show here.
EXPECTED_SCHEMAS = {
    "deploy/k8s/deployment.yaml#0": "kubernetes-models/apps/v1/Deployment",
    "deploy/k8s/service.yaml#0": "kubernetes-models/v1/Service",
    "deploy/k8s/pdb.yaml#0": "kubernetes-models/policy/v1/PodDisruptionBudget",
    "deploy/k8s/hpa.yaml#0": "kubernetes-models/autoscaling/v2/HorizontalPodAutoscaler",
    "deploy/k8s/batch/job.yaml#0": "kubernetes-models/batch/v1/Job",
}


def manifest_files():
    """Every *.yaml of the manifest folders but kustomization.yaml, which is no API object."""
    return [path for directory in MANIFEST_DIRS for path in sorted(directory.glob("*.yaml"))
            if path.name != "kustomization.yaml"]


def source_name(path, index):
    return f"{path.relative_to(SOURCE_DIR).as_posix()}#{index}"


def documents_of(text):
    return [document for document in yaml.safe_load_all(text) if document is not None]


def manifest_documents():
    """{"deploy/k8s/job.yaml#0": document} of every document of every manifest."""
    return {source_name(path, index): document
            for path in manifest_files()
            for index, document in enumerate(documents_of(path.read_text()))}


def validate(objects):
    """(exit code, {source: result}) of validate_k8s.mjs over {source: object}."""
    request = json.dumps([{"source": source, "object": obj} for source, obj in objects.items()])
    run = subprocess.run([NODE, str(VALIDATOR)], input=request, capture_output=True, text=True,
                         cwd=HERE, timeout=VALIDATE_TIMEOUT_SECONDS)
    if run.returncode not in (0, 1):
        raise AssertionError(f"validate_k8s.mjs failed ({run.returncode}):\n{run.stderr}")
    results = json.loads(run.stdout)
    return run.returncode, {result["source"]: result for result in results}


def describe(result):
    lines = [f"{result['source']} ({result['kind']} {result['name']}):"]
    lines += [f"  {e['path']}: {e['message']} [{e['keyword']}]" for e in result["errors"]]
    return "\n".join(lines)


def missing_tools():
    """Why the check cannot run here, or None."""
    if yaml is None:
        return "python3-yaml is not importable"
    if not NODE or not os.access(NODE, os.X_OK):
        return f"no node (TEMPOKEY_NODE={os.environ.get('TEMPOKEY_NODE')!r}, none on PATH)"
    if not (NODE_MODULES / "kubernetes-models" / "package.json").is_file():
        return f"{NODE_MODULES} has no kubernetes-models (npm ci there)"
    return None


def replace_once(old, new):
    """A text mutation: `old` must occur exactly once in the manifest."""
    def mutate(text):
        count = len(re.findall(old, text, re.M))
        if count != 1:
            raise AssertionError(f"{old!r} occurs {count} times in the manifest: "
                                 "update the mutation")
        return re.sub(old, new, text, flags=re.M)
    return mutate


def containers(document):
    return document["spec"]["template"]["spec"]["containers"]


def move_on_exit_codes_up(job):
    policy = job["spec"]["podFailurePolicy"]
    policy["onExitCodes"] = policy["rules"][0].pop("onExitCodes")


def name_the_grpc_port(deployment):
    containers(deployment)[0]["startupProbe"]["grpc"]["port"] = "grpc"


def move_readiness_service_up(deployment):
    probe = containers(deployment)[0]["readinessProbe"]
    probe["service"] = probe["grpc"].pop("service")


def add_autoscaling_v1_field(hpa):
    hpa["spec"]["targetCPUUtilizationPercentage"] = 70


def misspell_pdb_match_labels(pdb):
    selector = pdb["spec"]["selector"]
    selector["matchLabel"] = selector.pop("matchLabels")


def drop_container_name(deployment):
    del containers(deployment)[0]["name"]


def add_an_annotation(deployment):
    deployment["spec"]["template"]["metadata"]["annotations"]["example.com/any-key"] = "x"


JOB = "deploy/k8s/batch/job.yaml"
DEPLOYMENT = "deploy/k8s/deployment.yaml"
CONTAINER = "spec.template.spec.containers[0]"

# (what, manifest, text mutation or None, document mutation or None, {(path, keyword)} expected).
# Each is applied to a copy of the real manifest; the report must name exactly these fields.
MUTATIONS = [
    ("misspelled field", JOB,
     replace_once(r"^  backoffLimitPerIndex: 3$", "  backoffLimitPerIndx: 3"),
     None, {("spec.backoffLimitPerIndx", "unknown")}),
    ("string for an integer", JOB, replace_once(r"^  completions: 8$", '  completions: "8"'),
     None, {("spec.completions", "type")}),
    ("onExitCodes under podFailurePolicy, not a rule", JOB, None, move_on_exit_codes_up,
     {("spec.podFailurePolicy.onExitCodes", "unknown")}),
    ("value outside the enum", JOB, replace_once(r"^  completionMode: Indexed$",
                                                 "  completionMode: indexed"),
     None, {("spec.completionMode", "enum")}),
    ("string exit code", JOB, replace_once(r"^          values: \[2\]$", '          values: ["2"]'),
     None, {("spec.podFailurePolicy.rules[0].onExitCodes.values[0]", "type")}),
    ("port name in a grpc probe (which takes a number only)", DEPLOYMENT, None, name_the_grpc_port,
     {(f"{CONTAINER}.startupProbe.grpc.port", "type")}),
    ("grpc service beside grpc, not in it", DEPLOYMENT, None, move_readiness_service_up,
     {(f"{CONTAINER}.readinessProbe.service", "unknown")}),
    ("misspelled pod field", DEPLOYMENT, replace_once(r"^      terminationGracePeriodSeconds: 50$",
                                                      "      terminationGracePeriod: 50"),
     None, {("spec.template.spec.terminationGracePeriod", "unknown")}),
    ("required field missing", DEPLOYMENT, None, drop_container_name,
     {(f"{CONTAINER}.name", "required")}),
    ("misspelled kind", DEPLOYMENT, replace_once(r"^kind: Deployment$", "kind: Deploymnet"),
     None, {("kind", "kind")}),
    ("autoscaling/v1 field in an autoscaling/v2 object", "deploy/k8s/hpa.yaml", None,
     add_autoscaling_v1_field, {("spec.targetCPUUtilizationPercentage", "unknown")}),
    ("percent sign in an integer", "deploy/k8s/hpa.yaml",
     replace_once(r"averageUtilization: 70$", "averageUtilization: 70%"),
     None, {("spec.metrics[0].resource.target.averageUtilization", "type")}),
    ("misspelled field of a meta/v1 LabelSelector", "deploy/k8s/pdb.yaml", None,
     misspell_pdb_match_labels, {("spec.selector.matchLabel", "unknown")}),
    ("misspelled Service field", "deploy/k8s/service.yaml",
     replace_once(r"^  clusterIP: None$", "  clusterIp: None"),
     None, {("spec.clusterIp", "unknown")}),
    ("lower-case protocol", "deploy/k8s/service.yaml",
     replace_once(r"^      protocol: TCP$", "      protocol: tcp"),
     None, {("spec.ports[0].protocol", "enum")}),
    # The control: a new key in a map (annotations) is no unknown field.
    ("new annotation (allowed)", DEPLOYMENT, None, add_an_annotation, set()),
]


class KubernetesSchemaTest(unittest.TestCase):
    def test_kustomizations_list_every_manifest(self):
        for directory in MANIFEST_DIRS:
            with self.subTest(directory=directory.name):
                kustomization = yaml.safe_load((directory / "kustomization.yaml").read_text())
                on_disk = {p.name for p in directory.glob("*.yaml")} - {"kustomization.yaml"}
                self.assertEqual(set(kustomization["resources"]), on_disk)

    def test_installed_packages_are_the_locked_ones(self):
        lock = json.loads((HERE / "package-lock.json").read_text())
        pinned = json.loads((HERE / "package.json").read_text())["dependencies"]

        self.assertEqual(pinned, {"kubernetes-models": "5.1.0"}, "pinned exactly")
        for path, package in lock["packages"].items():
            if not path:
                continue
            with self.subTest(package=path):
                installed = json.loads((HERE / path / "package.json").read_text())["version"]
                self.assertEqual(installed, package["version"],
                                 "node_modules is stale: run deploy/install-deps.sh")

    def test_every_manifest_document_passes_the_schema(self):
        documents = manifest_documents()

        code, results = validate(documents)

        self.assertEqual({source: result["schema"] for source, result in results.items()},
                         EXPECTED_SCHEMAS)
        faults = [describe(result) for result in results.values() if result["errors"]]
        self.assertEqual(faults, [], "\n".join(faults))
        self.assertEqual(code, 0)

    def test_each_mistake_in_a_copy_of_a_manifest_is_reported(self):
        objects = {}
        expected = {}
        with tempfile.TemporaryDirectory() as directory:
            for what, manifest, edit_text, edit_document, fields in MUTATIONS:
                text = (SOURCE_DIR / manifest).read_text()
                if edit_text:
                    text = edit_text(text)
                copy_path = Path(directory) / Path(manifest).name
                copy_path.write_text(text)
                document = copy.deepcopy(documents_of(copy_path.read_text())[0])
                if edit_document:
                    edit_document(document)
                source = f"{manifest}#0 with {what}"
                objects[source] = document
                expected[source] = fields

        code, results = validate(objects)

        self.assertEqual(code, 1)
        for source, fields in expected.items():
            with self.subTest(mutation=source):
                result = results[source]
                reported = {(e["path"], e["keyword"]) for e in result["errors"]}
                self.assertEqual(reported, fields, describe(result))
                # The report names the document: its manifest, kind and name.
                self.assertEqual(result["source"], source)
                self.assertEqual((result["kind"], result["name"]),
                                 (objects[source]["kind"], objects[source]["metadata"]["name"]))
                self.assertTrue(all(e["message"] for e in result["errors"]), describe(result))


def main():
    reason = missing_tools()
    if reason:
        # CTest reads 77 as skipped (SKIP_RETURN_CODE in tests/deploy/CMakeLists.txt).
        print(f"skipped: {reason} (deploy/install-deps.sh installs it)")
        return 77
    program = unittest.main(exit=False, verbosity=2)
    return 0 if program.result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
