"""Checks deploy/k8s/ and deploy/compose.yaml against the rules of SPEC 7 and the server itself.

The manifests are plain YAML that no build compiles, so nothing else notices when a flag is
renamed, a port moves or the drain grows past the grace period. These tests hold them to:
every document parses; the CPU request equals --workers; gRPC probes (ready =
tempokey.v1.MotionService, live = ""); terminationGracePeriodSeconds covers the preStop pause,
the drain and the server's shutdown; the headless Service, the PodDisruptionBudget and the
HorizontalPodAutoscaler point at the Deployment; non-root uid 10001 with a locked-down context;
the ports in the args are the container ports; and every flag is one tempokey-server accepts.
The batch Job of deploy/k8s/batch/ (an Indexed Job whose pods each run one shard of `tempokey
batch`) is held to its own rules: the completion index is the shard, N is the completion count,
retries are per index, the target is the server's Service, the volumes are where the arguments
say, and its command line is one the real CLI accepts, with a pipeline file it parses.

Run by CTest (label `deploy`) as `/usr/bin/python3 test_manifests.py`; exits 77 (skipped) when
python3-yaml is missing. Environment: TEMPOKEY_SOURCE_DIR (default: two levels up) and
TEMPOKEY_SERVER, the built tempokey-server, whose --help lists the flags it accepts, and
TEMPOKEY_CLI, the built tempokey, which runs the batch Job's command line.
"""

import os
import re
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

try:
    import yaml
except ImportError:  # reported by main() below as a skip
    yaml = None

SOURCE_DIR = Path(os.environ.get("TEMPOKEY_SOURCE_DIR") or Path(__file__).resolve().parents[2])
K8S_DIR = SOURCE_DIR / "deploy" / "k8s"
BATCH_DIR = K8S_DIR / "batch"
COMPOSE_FILE = SOURCE_DIR / "deploy" / "compose.yaml"
DOCKERFILE = SOURCE_DIR / "Dockerfile"
SERVER_MAIN = SOURCE_DIR / "server" / "main.cc"
SERVER_CC = SOURCE_DIR / "server" / "server.cc"

READY_SERVICE = "tempokey.v1.MotionService"  # grpc.health.v1 name that is NOT_SERVING on drain
LIVE_SERVICE = ""                            # the server overall
IMAGE_UID = 10001                            # the Dockerfile's `tempokey` user
COMPOSE_REPLICAS = 3
HELP_TIMEOUT_SECONDS = 30


def parse_flags(tokens):
    """Returns {name: value} for `--name=value`, `--name value` and bare `--name` (value None).

    A bare flag followed by a token that is not a flag takes it as its value, as absl does for
    every type but bool; tempokey's only bool flags are given bare here, so this reads them right.
    """
    flags = {}
    i = 0
    while i < len(tokens):
        token = str(tokens[i])
        if not token.startswith("--"):
            raise ValueError(f"argument {i} ({token!r}) is not a --flag")
        name, equals, value = token[2:].partition("=")
        if not equals:
            value = None
            if i + 1 < len(tokens) and not str(tokens[i + 1]).startswith("-"):
                value = str(tokens[i + 1])
                i += 1
        if name in flags:
            raise ValueError(f"--{name} is given twice")
        flags[name] = value
        i += 1
    return flags


def port_of(address):
    """The port of `host:port` (host may be empty or an IPv6 literal in brackets)."""
    return int(address.rsplit(":", 1)[1])


def cpu_quantity(value):
    """Kubernetes CPU quantity ("2", 2, "1500m") in CPUs."""
    text = str(value)
    return int(text[:-1]) / 1000 if text.endswith("m") else float(text)


def duration_seconds(text):
    """A compose duration ("45s", "1m30s") in seconds."""
    parts = re.fullmatch(r"(?:(\d+)m)?(?:(\d+)s)?", str(text))
    if parts is None or not any(parts.groups()):
        raise ValueError(f"unsupported duration {text!r}")
    minutes, seconds = (int(g) if g else 0 for g in parts.groups())
    return 60 * minutes + seconds


def source_flags():
    """{name: C++ type} of every ABSL_FLAG in server/main.cc."""
    text = SERVER_MAIN.read_text()
    return {name: kind.strip()
            for kind, name in re.findall(r"ABSL_FLAG\(\s*([^,]+?)\s*,\s*(\w+)\s*,", text)}


def server_shutdown_overhead_seconds():
    """Worst case the server spends after the drain grace: cancel settle + gRPC Shutdown."""
    text = SERVER_CC.read_text()
    seconds = {}
    for name in ("kCancelSettleTime", "kShutdownCallDeadline"):
        found = re.search(name + r"\{(\d+)\}", text)
        if found is None:
            raise AssertionError(f"{name} not found in {SERVER_CC}: update this test with the "
                                 "server's drain sequence (Server::Drain)")
        seconds[name] = int(found.group(1))
    return sum(seconds.values())


def dockerfile_entrypoint():
    text = DOCKERFILE.read_text()
    found = re.search(r"^ENTRYPOINT\s+(\[.*\])\s*$", text, re.M)
    if found is None:
        raise AssertionError("the Dockerfile has no exec-form ENTRYPOINT")
    return yaml.safe_load(found.group(1))  # a JSON array is YAML too


def load_k8s(directory=K8S_DIR):
    """[(file name, document)] of every resource `directory`/kustomization.yaml lists, in order."""
    kustomization = yaml.safe_load((directory / "kustomization.yaml").read_text())
    documents = []
    for resource in kustomization["resources"]:
        for document in yaml.safe_load_all((directory / resource).read_text()):
            if document is not None:
                documents.append((resource, document))
    return documents


def env_references(text):
    """The names of the $(VAR) references Kubernetes expands in a command or an argument."""
    return set(re.findall(r"\$\(([A-Za-z_][A-Za-z0-9_]*)\)", text))


class ManifestTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.documents = load_k8s()
        cls.deployment = cls.one_of_kind("Deployment")
        cls.pod = cls.deployment["spec"]["template"]
        cls.pod_labels = cls.pod["metadata"]["labels"]
        containers = cls.pod["spec"]["containers"]
        assert len(containers) == 1, "one container per pod: the server"
        cls.container = containers[0]
        cls.args = parse_flags(cls.container.get("args", []))
        cls.ports = {p["name"]: p["containerPort"] for p in cls.container["ports"]}

    @classmethod
    def one_of_kind(cls, kind):
        found = [doc for _, doc in cls.documents if doc.get("kind") == kind]
        assert len(found) == 1, f"expected one {kind}, found {len(found)}"
        return found[0]

    def assertSelects(self, selector, what):
        self.assertTrue(selector, f"{what} has an empty selector (it would select every pod)")
        missing = {k: v for k, v in selector.items() if self.pod_labels.get(k) != v}
        self.assertEqual(missing, {}, f"{what} selects labels the Deployment's pods lack")

    def test_every_document_parses_and_is_listed(self):
        listed = {name for name, _ in self.documents}
        on_disk = {p.name for p in K8S_DIR.glob("*.yaml")} - {"kustomization.yaml"}

        kinds = sorted(doc["kind"] for _, doc in self.documents)

        self.assertEqual(listed, on_disk, "kustomization.yaml must list every manifest")
        self.assertEqual(kinds, ["Deployment", "HorizontalPodAutoscaler",
                                 "PodDisruptionBudget", "Service"])
        for name, doc in self.documents:
            self.assertIn("apiVersion", doc, name)
            self.assertIn("name", doc.get("metadata", {}), name)
        self.assertIsInstance(yaml.safe_load(COMPOSE_FILE.read_text()), dict)

    def test_cpu_request_equals_worker_count(self):
        cpu_request = cpu_quantity(self.container["resources"]["requests"]["cpu"])

        workers = int(self.args["workers"])

        self.assertGreater(workers, 0, "--workers=0 means 'detect', which the request cannot match")
        self.assertEqual(cpu_request, workers, "CPU request must equal --workers")

    def test_probes_are_native_grpc_on_live_and_ready(self):
        grpc_port = self.ports["grpc"]

        readiness = self.container["readinessProbe"]["grpc"]
        liveness = self.container["livenessProbe"]["grpc"]
        startup = self.container["startupProbe"]["grpc"]

        self.assertEqual(readiness.get("service"), READY_SERVICE)
        self.assertEqual(liveness.get("service", LIVE_SERVICE), LIVE_SERVICE)
        self.assertEqual(startup.get("service", LIVE_SERVICE), LIVE_SERVICE)
        for probe in (readiness, liveness, startup):
            self.assertEqual(probe["port"], grpc_port, "probes must ask the gRPC port")

    def test_grace_period_covers_prestop_drain_and_shutdown(self):
        pre_stop = self.container["lifecycle"]["preStop"]
        if "sleep" in pre_stop:  # native handler, Kubernetes >= 1.30
            pre_stop_seconds = int(pre_stop["sleep"]["seconds"])
        else:
            command = pre_stop["exec"]["command"]
            self.assertEqual(Path(command[0]).name, "sleep", "preStop must be a plain pause")
            pre_stop_seconds = int(command[1])
        drain_seconds = int(self.args["drain_grace_seconds"])
        grace_seconds = self.pod["spec"]["terminationGracePeriodSeconds"]

        needed = pre_stop_seconds + drain_seconds + server_shutdown_overhead_seconds()

        self.assertGreater(pre_stop_seconds, 0)
        self.assertGreater(grace_seconds, needed,
                           f"terminationGracePeriodSeconds {grace_seconds} must exceed preStop "
                           f"{pre_stop_seconds} + drain {drain_seconds} + shutdown")

    def test_max_connection_age_makes_clients_rebalance(self):
        self.assertGreater(int(self.args["max_connection_age_seconds"]), 0)

    def test_headless_service_selects_the_pods(self):
        service = self.one_of_kind("Service")
        deployment_selector = self.deployment["spec"]["selector"]["matchLabels"]

        target_ports = [p["targetPort"] for p in service["spec"]["ports"]]

        self.assertEqual(service["spec"].get("clusterIP"), "None", "the Service must be headless")
        self.assertSelects(service["spec"]["selector"], "the Service")
        self.assertSelects(deployment_selector, "the Deployment's selector")
        for target in target_ports:
            self.assertIn(target, list(self.ports) + list(self.ports.values()))
        self.assertIn("grpc", [p["name"] for p in service["spec"]["ports"]])

    def test_pod_disruption_budget_selects_the_pods(self):
        pdb = self.one_of_kind("PodDisruptionBudget")

        self.assertSelects(pdb["spec"]["selector"]["matchLabels"], "the PodDisruptionBudget")
        self.assertTrue({"maxUnavailable", "minAvailable"} & set(pdb["spec"]))

    def test_autoscaler_targets_the_deployment(self):
        hpa = self.one_of_kind("HorizontalPodAutoscaler")

        target = hpa["spec"]["scaleTargetRef"]

        self.assertEqual(target["kind"], "Deployment")
        self.assertEqual(target["apiVersion"], "apps/v1")
        self.assertEqual(target["name"], self.deployment["metadata"]["name"])
        self.assertGreaterEqual(hpa["spec"]["minReplicas"], 2,
                                "with one replica the disruption budget can never let it go")

    def test_runs_as_the_image_user_locked_down(self):
        pod_context = self.pod["spec"].get("securityContext", {})
        context = {**pod_context, **self.container.get("securityContext", {})}

        image_user = re.search(r"^USER\s+(\S+)", DOCKERFILE.read_text(), re.M)

        self.assertIs(context.get("runAsNonRoot"), True)
        self.assertEqual(context.get("runAsUser"), IMAGE_UID)
        self.assertEqual(image_user and image_user.group(1), str(IMAGE_UID))
        self.assertIs(context.get("allowPrivilegeEscalation"), False)
        self.assertIs(context.get("readOnlyRootFilesystem"), True)
        self.assertEqual(context.get("capabilities", {}).get("drop"), ["ALL"])

    def test_arg_ports_are_the_container_ports(self):
        annotations = self.pod["metadata"].get("annotations", {})

        grpc_port = port_of(self.args["address"])
        metrics_port = port_of(self.args["metrics_address"])

        self.assertEqual(grpc_port, self.ports["grpc"])
        self.assertEqual(metrics_port, self.ports["metrics"])
        self.assertEqual(annotations.get("prometheus.io/scrape"), "true")
        self.assertEqual(annotations.get("prometheus.io/port"), str(metrics_port))

    def test_command_is_the_image_entrypoint(self):
        entrypoint = dockerfile_entrypoint()

        image_flags = parse_flags(entrypoint[1:])

        self.assertEqual(self.container.get("command", entrypoint[:1]), entrypoint[:1])
        for name, value in image_flags.items():
            self.assertIn(name, self.args, f"the Dockerfile's --{name} is missing from args")
            self.assertEqual(self.args[name], value, f"--{name} differs from the Dockerfile's")

    def test_image_is_never_pulled_from_a_registry_by_default(self):
        self.assertEqual(self.container["image"].rsplit(":", 1)[0], "tempokey")
        self.assertIn(self.container.get("imagePullPolicy"), ("IfNotPresent", "Never"))

    def test_args_are_flags_the_server_declares(self):
        declared = source_flags()

        for name, value in self.args.items():
            with self.subTest(flag=name):
                self.assertIn(name, declared, f"--{name} is not an ABSL_FLAG in server/main.cc")
                kind = declared[name]
                if kind == "bool":
                    self.assertIn(value, (None, "true", "false"))
                elif kind in ("int", "int64_t"):
                    self.assertRegex(str(value), r"^-?\d+$")
                else:
                    self.assertIsNotNone(value, f"--{name} needs a value")

    def test_args_are_flags_the_server_binary_accepts(self):
        server = os.environ.get("TEMPOKEY_SERVER")
        if not server or not os.access(server, os.X_OK):
            self.skipTest(f"no tempokey-server binary (TEMPOKEY_SERVER={server!r}): build it")

        # --help lists the server's own flags, one line each: "  --name   help (default: v)".
        help_text = subprocess.run([server, "--help"], capture_output=True, text=True,
                                   timeout=HELP_TIMEOUT_SECONDS).stdout
        accepted = set(re.findall(r"^  --(\w+) ", help_text, re.M))

        self.assertIn("address", accepted, "could not read tempokey-server --help")
        self.assertEqual(set(self.args) - accepted, set())
        self.assertEqual(set(parse_flags(dockerfile_entrypoint()[1:])) - accepted, set())


class BatchJobTest(unittest.TestCase):
    """deploy/k8s/batch/: the Indexed Job that runs a batch's shards against the Service."""

    SHARD_ARG = re.compile(r"^--shard=\$\(JOB_COMPLETION_INDEX\)/(\d+)$")

    @classmethod
    def setUpClass(cls):
        cls.kustomization = yaml.safe_load((BATCH_DIR / "kustomization.yaml").read_text())
        cls.documents = load_k8s(BATCH_DIR)
        jobs = [doc for _, doc in cls.documents if doc.get("kind") == "Job"]
        assert len(jobs) == 1, "deploy/k8s/batch holds one Job"
        cls.job = jobs[0]
        cls.pod = cls.job["spec"]["template"]
        containers = cls.pod["spec"]["containers"]
        assert len(containers) == 1, "one container per pod: the CLI"
        cls.container = containers[0]
        cls.args = [str(a) for a in cls.container["args"]]
        cls.command_index = cls.args.index("batch")
        cls.env = {e["name"]: e for e in cls.container.get("env", [])}
        cls.mounts = {m["name"]: m for m in cls.container["volumeMounts"]}
        cls.volumes = {v["name"]: v for v in cls.pod["spec"]["volumes"]}
        server_documents = load_k8s()
        cls.service = [doc for _, doc in server_documents if doc["kind"] == "Service"][0]
        cls.server_set = server_documents

    def flag(self, name):
        """The value of --name=value in the batch command's arguments, or None."""
        for arg in self.args[self.command_index + 1:]:
            if arg.startswith("--%s=" % name):
                return arg.split("=", 1)[1]
        return None

    def mount_of(self, path):
        """The volume mount whose mountPath contains `path`."""
        found = [m for m in self.mounts.values() if path == m["mountPath"]
                 or path.startswith(m["mountPath"].rstrip("/") + "/")]
        self.assertEqual(len(found), 1, "%s is on no mounted volume" % path)
        return found[0]

    def test_every_manifest_is_listed_and_none_is_in_the_server_set(self):
        listed = {name for name, _ in self.documents}
        on_disk = {p.name for p in BATCH_DIR.glob("*.yaml")} - {"kustomization.yaml"}
        server_kinds = {doc["kind"] for _, doc in self.server_set}

        self.assertEqual(listed, on_disk)
        self.assertEqual(self.job["apiVersion"], "batch/v1")
        self.assertNotIn("Job", server_kinds,
                         "applying the server set (kubectl apply -k deploy/k8s) must not start "
                         "a run")

    def test_completion_index_is_the_shard_of_as_many_shards_as_completions(self):
        spec = self.job["spec"]
        shard_args = [a for a in self.args if self.SHARD_ARG.match(a)]
        index_env = self.env["JOB_COMPLETION_INDEX"]["valueFrom"]["fieldRef"]["fieldPath"]

        self.assertEqual(spec["completionMode"], "Indexed")
        self.assertEqual(len(shard_args), 1, "--shard=$(JOB_COMPLETION_INDEX)/N")
        self.assertEqual(int(self.SHARD_ARG.match(shard_args[0]).group(1)), spec["completions"])
        self.assertGreaterEqual(spec["parallelism"], 1)
        self.assertLessEqual(spec["parallelism"], spec["completions"])
        self.assertEqual(index_env,
                         "metadata.annotations['batch.kubernetes.io/job-completion-index']")

    def test_retries_are_per_shard_and_usage_errors_stop_the_job(self):
        spec = self.job["spec"]
        rules = spec["podFailurePolicy"]["rules"]

        fail_job = [r for r in rules if r["action"] == "FailJob"]
        ignore = [r for r in rules if r["action"] == "Ignore"]

        self.assertGreaterEqual(spec["backoffLimitPerIndex"], 1)
        self.assertEqual(self.pod["spec"]["restartPolicy"], "Never",
                         "backoffLimitPerIndex and podFailurePolicy need restartPolicy Never")
        self.assertEqual(len(fail_job), 1)
        self.assertEqual(fail_job[0]["onExitCodes"]["containerName"], self.container["name"])
        self.assertEqual(fail_job[0]["onExitCodes"]["values"], [2], "exit 2: a usage error")
        self.assertEqual(ignore[0]["onPodConditions"], [{"type": "DisruptionTarget"}])

    def test_target_is_the_servers_headless_service(self):
        server = [a for a in self.args[:self.command_index] if a.startswith("--server=")]
        self.assertEqual(len(server), 1)
        target = server[0].split("=", 1)[1]
        grpc_port = [p["port"] for p in self.service["spec"]["ports"] if p["name"] == "grpc"][0]

        match = re.fullmatch(r"dns:///([^.]+)\.\$\(POD_NAMESPACE\)\.svc\.cluster\.local:(\d+)",
                             target)

        self.assertIsNotNone(match, target)
        self.assertEqual(match.group(1), self.service["metadata"]["name"])
        self.assertEqual(int(match.group(2)), grpc_port)
        self.assertEqual(self.env["POD_NAMESPACE"]["valueFrom"]["fieldRef"]["fieldPath"],
                         "metadata.namespace")

    def test_every_expanded_variable_is_defined(self):
        for arg in self.args + [str(c) for c in self.container["command"]]:
            with self.subTest(arg=arg):
                self.assertEqual(env_references(arg) - set(self.env), set())

    def test_pods_are_not_servers_to_the_service(self):
        labels = self.pod["metadata"]["labels"]
        selector = self.service["spec"]["selector"]

        self.assertNotEqual({k: labels.get(k) for k in selector}, selector,
                            "the Service would send gRPC calls to batch pods")

    def test_volumes_are_where_the_arguments_say(self):
        captures = self.mount_of(self.args[self.command_index + 1])
        curves = self.mount_of(self.flag("output"))
        pipeline = self.mount_of(self.flag("ops"))
        summary = self.mount_of(self.flag("summary"))
        generated = [g["name"] for g in self.kustomization["configMapGenerator"]]

        self.assertIs(captures.get("readOnly"), True, "the captures are only read")
        self.assertIs(self.volumes[captures["name"]]["persistentVolumeClaim"].get("readOnly"), True)
        self.assertFalse(curves.get("readOnly", False), "the outputs are written")
        self.assertEqual(summary["name"], curves["name"], "summaries land beside the outputs")
        self.assertIn("persistentVolumeClaim", self.volumes[curves["name"]])
        self.assertIn(self.volumes[pipeline["name"]]["configMap"]["name"], generated)
        self.assertIn(Path(self.flag("ops")).name,
                      [Path(f).name for g in self.kustomization["configMapGenerator"]
                       for f in g["files"]])

    def test_runs_as_the_image_user_locked_down(self):
        context = {**self.pod["spec"].get("securityContext", {}),
                   **self.container.get("securityContext", {})}

        self.assertIs(context.get("runAsNonRoot"), True)
        self.assertEqual(context.get("runAsUser"), IMAGE_UID)
        self.assertIs(context.get("allowPrivilegeEscalation"), False)
        self.assertIs(context.get("readOnlyRootFilesystem"), True)
        self.assertEqual(context.get("capabilities", {}).get("drop"), ["ALL"])
        self.assertEqual(self.container["command"], ["/usr/local/bin/tempokey"])
        self.assertIn("/build/client/tempokey", DOCKERFILE.read_text(),
                      "the image ships the CLI the Job runs")
        self.assertEqual(self.container["image"].rsplit(":", 1)[0], "tempokey")
        self.assertIn(self.container.get("imagePullPolicy"), ("IfNotPresent", "Never"))

    def test_the_real_cli_accepts_the_command_line_and_the_pipeline(self):
        cli = os.environ.get("TEMPOKEY_CLI")
        if not cli or not os.access(cli, os.X_OK):
            self.skipTest("no tempokey binary (TEMPOKEY_CLI=%r): build it" % cli)
        with tempfile.TemporaryDirectory() as directory:
            # Each mount becomes a local folder; the ConfigMap's files are the ones kustomize
            # puts in it.
            local = {}
            for name, mount in self.mounts.items():
                volume = self.volumes[name]
                if "configMap" in volume:
                    local[mount["mountPath"]] = str(BATCH_DIR)
                else:
                    local[mount["mountPath"]] = os.path.join(directory, name)
                    os.mkdir(local[mount["mountPath"]])
            values = {"JOB_COMPLETION_INDEX": "3", "POD_NAMESPACE": "studio"}
            argv = []
            for arg in self.args:
                arg = re.sub(r"\$\((\w+)\)", lambda m: values[m.group(1)], arg)
                for mount_path, path in sorted(local.items(), key=lambda i: -len(i[0])):
                    arg = re.sub(r"(^|=)" + re.escape(mount_path) + r"(?=/|$)",
                                 lambda m: m.group(1) + path, arg)
                argv.append(arg)

            run = subprocess.run([cli] + argv, capture_output=True, text=True,
                                 timeout=HELP_TIMEOUT_SECONDS)

        # Every flag and the pipeline were accepted (a mistake in either is exit 2); the run
        # then stops at the empty captures folder, before any server is needed.
        captures = local[self.mounts["captures"]["mountPath"]]
        self.assertEqual((run.returncode, run.stderr),
                         (1, "error: %s: no .bvh files\n" % captures), " ".join(argv))


class ComposeTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.text = COMPOSE_FILE.read_text()
        cls.services = yaml.safe_load(cls.text)["services"]

    def grpc_host_ports(self):
        ports = []
        for name, service in sorted(self.services.items()):
            for mapping in service["ports"]:
                host_ip, host_port, container_port = str(mapping).split(":")
                if int(container_port) == 50051:
                    self.assertEqual(host_ip, "127.0.0.1", f"{name}: plaintext gRPC on loopback")
                    ports.append(int(host_port))
        return ports

    def test_three_servers_on_distinct_loopback_ports(self):
        ports = self.grpc_host_ports()

        self.assertEqual(len(self.services), COMPOSE_REPLICAS)
        self.assertEqual(len(ports), COMPOSE_REPLICAS)
        self.assertEqual(len(set(ports)), COMPOSE_REPLICAS)

    def test_documented_cli_target_lists_every_server(self):
        target = ",".join(f"127.0.0.1:{port}" for port in sorted(self.grpc_host_ports()))

        self.assertIn(f"--server ipv4:{target}", self.text)

    def test_stop_drains_within_the_grace(self):
        declared = source_flags()

        for name, service in self.services.items():
            with self.subTest(service=name):
                flags = parse_flags(service["command"])
                drain_seconds = int(flags["drain_grace_seconds"])
                self.assertEqual(set(flags) - set(declared), set(), "unknown server flags")
                self.assertEqual(service.get("stop_signal"), "SIGTERM")
                self.assertGreater(duration_seconds(service["stop_grace_period"]),
                                   drain_seconds + server_shutdown_overhead_seconds())


def main():
    if yaml is None:
        # CTest reads 77 as skipped (SKIP_RETURN_CODE in tests/deploy/CMakeLists.txt).
        print("skipped: python3-yaml is not importable (deploy/install-deps.sh installs it)")
        return 77
    program = unittest.main(exit=False, verbosity=2)
    return 0 if program.result.wasSuccessful() else 1


if __name__ == "__main__":
    sys.exit(main())
