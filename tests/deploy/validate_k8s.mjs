// Checks Kubernetes API objects against the Kubernetes API's own OpenAPI schema, as compiled by
// the npm package kubernetes-models (pinned in tests/deploy/package.json and package-lock.json,
// installed by deploy/install-deps.sh), plus the one rule those schemas leave out: no unknown
// fields.
//
//   node validate_k8s.mjs < objects.json
//
// stdin: a JSON array of {"source": "deploy/k8s/job.yaml#0", "object": {...}} (the YAML is turned
// into JSON by tests/deploy/test_k8s_schema.py with python3-yaml). stdout: a JSON array, one entry
// per input in order: {"source", "apiVersion", "kind", "name", "schema", "errors": [{"path",
// "keyword", "message"}]}, with `path` the field's path in the object
// (spec.template.spec.containers[0].startupProbe.grpc.port). Exit 0 when no object has an error,
// 1 when one has, 2 when the input or the packages cannot be read.
//
// Which Kubernetes: kubernetes-models 5.x is generated from Kubernetes v1.36 (upstream
// CHANGELOG, 5.0.0: "Update to Kubernetes v1.36.0"; the README's 1.27.1 badge is stale). In
// node_modules: kubernetes-models/v1/PodSpec.d.ts:185 declares "schedulingGroup", the Pod field
// of Kubernetes 1.36 (1.35's alpha was spec.workloadRef, which is absent). The fields the
// manifests use are all there: batch/v1/JobSpec.d.ts:21 backoffLimitPerIndex, :35
// completionMode, :59 podFailurePolicy; batch/v1/PodFailurePolicyRule.d.ts:31 onExitCodes, :35
// onPodConditions; v1/Probe.d.ts:21 grpc and v1/GRPCAction.d.ts:9 port (required integer);
// autoscaling/v2/HorizontalPodAutoscalerSpec.d.ts:12 behavior, :20 metrics;
// autoscaling/v2/MetricTarget.d.ts:10 averageUtilization; policy/v1/PodDisruptionBudgetSpec.d.ts:11
// maxUnavailable; v1/ServicePort.d.ts:19 appProtocol. The package also keeps API versions that
// newer Kubernetes removed (policy/v1beta1, extensions/v1beta1...): it is merged from several
// Kubernetes versions, so an object of a removed version still validates here.
//
// Why the unknown-field rule is ours: the compiled schemas never reject an unknown property.
// kubernetes-models/_schemas/IoK8sApiBatchV1JobSpec.js (one minified line, line 1): function
// validate2 tests each declared property as `void 0!==data.backoffLimitPerIndex&&(...)` and has
// no additionalProperties branch, so {"backoffLimitPerIndx": 3} passes; across all of
// kubernetes-models/_schemas/*.js and @kubernetes-models/apimachinery/_schemas/*.js the only
// keywords reported are type, required, enum, format and oneOf (`grep -o 'keyword:"[a-zA-Z]*"'`),
// never additionalProperties. (kube-apiserver's strict field validation, `kubectl apply
// --validate=strict`, does reject unknown fields.)
//
// How the rule is added: the schema exists here only as this compiled code, so the validator
// itself is made to show which properties each object's schema declares. The object is
// validated through a Proxy that records every own property the validator reads. A compiled
// object schema reads exactly its declared properties (`data.<name>`, as above); a map
// (labels, annotations, resources.requests: additionalProperties with a schema) reads every key
// (`for(let key0 in data) validate1(data[key0], ...)`, IoK8sApiCoreV1ResourceRequirements.js).
// The validators run in all-errors mode (each property is checked even after an earlier error,
// errors are pushed and counted, never returned early), so every declared property is read.
// An own property of an object that was never read is a field the schema does not declare:
// reported as keyword "unknown". An object whose own type is wrong (an object where a string
// goes) is reported once, by its type error, not field by field. A free-form object (a schema
// with no properties, as RawExtension) would have every field reported; these manifests have
// none. test_k8s_schema.py holds this to account both ways: its unknown-field mutations fail if
// nothing is reported, and the real manifests and a new annotation key fail if too much is.

import { existsSync } from "node:fs";

const DOTTED = /^[A-Za-z_][A-Za-z0-9_-]*$/;

function formatPath(segments) {
  let text = "";
  for (const segment of segments) {
    if (typeof segment === "number") text += `[${segment}]`;
    else if (DOTTED.test(segment)) text += (text ? "." : "") + segment;
    else text += `[${JSON.stringify(segment)}]`;
  }
  return text || "(the object)";
}

// JSON pointer (ajv's instancePath) to path segments; numeric segments under arrays are indexes.
function pointerSegments(pointer, root) {
  const segments = [];
  let node = root;
  for (const raw of pointer.split("/").slice(1)) {
    const key = raw.replace(/~1/g, "/").replace(/~0/g, "~");
    if (Array.isArray(node)) {
      segments.push(Number(key));
      node = node[Number(key)];
    } else {
      segments.push(key);
      node = node && typeof node === "object" ? node[key] : undefined;
    }
  }
  return segments;
}

// A Proxy over `value` (and, lazily, over each object or array the validator reaches through it)
// that records which own properties were read. Each property yields the same child Proxy every
// time, so repeated reads of one field land in one record.
function track(value, segments, records) {
  if (value === null || typeof value !== "object") return value;
  const record = { value, segments, read: new Set() };
  records.push(record);
  const children = new Map();
  return new Proxy(value, {
    get(target, key, receiver) {
      if (typeof key === "string" && Object.prototype.hasOwnProperty.call(target, key)) {
        record.read.add(key);
        if (!children.has(key)) {
          const index = Array.isArray(target) ? Number(key) : key;
          children.set(key, track(target[key], [...segments, index], records));
        }
        return children.get(key);
      }
      return Reflect.get(target, key, receiver);
    },
  });
}

const API_VERSION = /^(?:[a-z0-9]([a-z0-9.-]*[a-z0-9])?\/)?v[0-9]+(?:(?:alpha|beta)[0-9]+)?$/;
const KIND = /^[A-Z][A-Za-z0-9]*$/;

async function modelOf(apiVersion, kind) {
  if (typeof apiVersion !== "string" || !API_VERSION.test(apiVersion)) {
    const shown = JSON.stringify(apiVersion);
    return { path: "apiVersion", error: `${shown} is not GROUP/VERSION or v1` };
  }
  if (typeof kind !== "string" || !KIND.test(kind)) {
    return { path: "kind", error: `${JSON.stringify(kind)} is not a Kubernetes kind name` };
  }
  let module;
  try {
    module = await import(`kubernetes-models/${apiVersion}/${kind}`);
  } catch (error) {
    if (error.code === "ERR_MODULE_NOT_FOUND" || error.code === "ERR_PACKAGE_PATH_NOT_EXPORTED") {
      return { path: "kind", error: `no kind ${kind} in apiVersion ${apiVersion}` };
    }
    throw error;
  }
  const model = module[kind];
  // Only top-level resources carry apiVersion and kind (apps/v1/DeploymentSpec does not).
  if (!model || model.apiVersion !== apiVersion || model.kind !== kind) {
    return { path: "kind", error: `${kind} is not a resource kind of apiVersion ${apiVersion}` };
  }
  return { model };
}

async function check(object) {
  const result = {
    apiVersion: object?.apiVersion,
    kind: object?.kind,
    name: object?.metadata?.name,
    schema: null,
    errors: [],
  };
  if (object === null || typeof object !== "object" || Array.isArray(object)) {
    result.errors.push({ path: "(the object)", keyword: "type", message: "must be an object" });
    return result;
  }
  const { model, path, error } = await modelOf(object.apiVersion, object.kind);
  if (error) {
    result.errors.push({ path, keyword: "kind", message: error });
    return result;
  }
  result.schema = `kubernetes-models/${object.apiVersion}/${object.kind}`;

  const records = [];
  const tracked = track(object, [], records);
  let schemaErrors = [];
  try {
    // The model's validate() runs the compiled schema on `this` (@kubernetes-models/base
    // setValidateFunc -> runValidateFunc(fn, this)): here, the tracking Proxy.
    model.prototype.validate.call(tracked);
  } catch (thrown) {
    if (!Array.isArray(thrown?.errors)) throw thrown;
    schemaErrors = thrown.errors;
  }

  const typeErrors = new Set();
  for (const e of schemaErrors) {
    const segments = pointerSegments(e.instancePath, object);
    if (e.keyword === "required") segments.push(e.params.missingProperty);
    if (e.keyword === "type") typeErrors.add(formatPath(segments));
    result.errors.push({ path: formatPath(segments), keyword: e.keyword, message: e.message });
  }
  for (const record of records) {
    const { value, segments, read } = record;
    if (Array.isArray(value) || typeErrors.has(formatPath(segments))) continue;
    for (const key of Object.keys(value)) {
      if (!read.has(key)) {
        result.errors.push({
          path: formatPath([...segments, key]),
          keyword: "unknown",
          message: `unknown field "${key}" (not in the ${object.apiVersion} ${object.kind} schema)`,
        });
      }
    }
  }
  // oneOf (int-or-string, quantities) reports each failed branch; one line per path and message.
  const seen = new Set();
  result.errors = result.errors.filter((e) => {
    const key = `${e.path}\u0000${e.keyword}\u0000${e.message}`;
    return seen.has(key) ? false : (seen.add(key), true);
  });
  return result;
}

async function readStdin() {
  const chunks = [];
  for await (const chunk of process.stdin) chunks.push(chunk);
  return Buffer.concat(chunks).toString("utf8");
}

async function main() {
  if (!existsSync(new URL("node_modules/kubernetes-models/package.json", import.meta.url))) {
    process.stderr.write("validate_k8s: tests/deploy/node_modules/kubernetes-models is missing " +
                         "(deploy/install-deps.sh runs npm ci there)\n");
    return 2;
  }
  let inputs;
  try {
    inputs = JSON.parse(await readStdin());
    if (!Array.isArray(inputs)) throw new Error("stdin is not a JSON array");
  } catch (error) {
    process.stderr.write(`validate_k8s: ${error.message}\n`);
    return 2;
  }
  const results = [];
  for (const { source, object } of inputs) {
    results.push({ source, ...(await check(object)) });
  }
  process.stdout.write(JSON.stringify(results, null, 1) + "\n");
  return results.some((r) => r.errors.length > 0) ? 1 : 0;
}

main().then(
  (code) => process.exit(code),
  (error) => {
    process.stderr.write(`validate_k8s: ${error.stack || error}\n`);
    process.exit(2);
  },
);
