// Validates every manifest under deploy/k8s against the Kubernetes API schemas
// (kubernetes-models), offline, and checks each kustomization's references resolve.
// Usage: node validate_k8s.mjs DEPLOY_K8S_DIR. Exit 1 naming the file and the problem.
import fs from "node:fs";
import path from "node:path";
import YAML from "yaml";
import k8s from "@kubernetes/client-node";

const root = process.argv[2];
const models = {
  "apps/v1": {
    StatefulSet: (await import("kubernetes-models/apps/v1/StatefulSet")).StatefulSet,
    Deployment: (await import("kubernetes-models/apps/v1/Deployment")).Deployment,
  },
  v1: {
    Service: (await import("kubernetes-models/v1/Service")).Service,
    Secret: (await import("kubernetes-models/v1/Secret")).Secret,
    Namespace: (await import("kubernetes-models/v1/Namespace")).Namespace,
  },
  "policy/v1": { PodDisruptionBudget: (await import("kubernetes-models/policy/v1/PodDisruptionBudget")).PodDisruptionBudget },
  "autoscaling/v2": {
    HorizontalPodAutoscaler: (await import("kubernetes-models/autoscaling/v2/HorizontalPodAutoscaler"))
      .HorizontalPodAutoscaler,
  },
};

// The API's field list of every type (the client's generated models): a field a type does
// not have is a misspelling, which the schemas above let through (they allow extra keys).
function unknownFields(obj, type, where, out) {
  if (obj === null || obj === undefined) return;
  if (type.startsWith("Array<")) {
    if (Array.isArray(obj)) obj.forEach((v, i) => unknownFields(v, type.slice(6, -1), `${where}[${i}]`, out));
    return;
  }
  const map = type.match(/^\{ \[key: string\]: (.*); \}$/);
  if (map) {
    for (const [k, v] of Object.entries(obj)) unknownFields(v, map[1], `${where}.${k}`, out);
    return;
  }
  const model = k8s[type];
  if (!model?.getAttributeTypeMap || typeof obj !== "object") return;  // strings, numbers, IntOrString
  const fields = model.getAttributeTypeMap();
  const names = new Set(fields.map((f) => f.baseName));
  for (const k of Object.keys(obj)) if (!names.has(k)) out.push(`${where}.${k}: ${type} has no field '${k}'`);
  for (const f of fields) unknownFields(obj[f.baseName], f.type, `${where}.${f.baseName}`, out);
}
const modelName = (obj) => obj.apiVersion.split("/").pop().toUpperCase().replace(/^V/, "V") + obj.kind;

let failures = 0, checked = 0;
const fail = (file, why) => {
  console.error(`${path.relative(root, file)}: ${why}`);
  failures++;
};
const walk = (dir) => fs.readdirSync(dir, { withFileTypes: true }).flatMap((e) =>
  e.isDirectory() ? walk(path.join(dir, e.name)) : [path.join(dir, e.name)]);

for (const file of walk(root).filter((f) => f.endsWith(".yaml"))) {
  let docs;
  try {
    docs = YAML.parseAllDocuments(fs.readFileSync(file, "utf8"));
  } catch (e) {
    fail(file, `not YAML: ${e.message}`);
    continue;
  }
  for (const doc of docs) {
    if (doc.errors.length) {
      fail(file, `not YAML: ${doc.errors[0].message}`);
      continue;
    }
    const obj = doc.toJS();
    if (!obj) continue;
    if (obj.kind === "Kustomization") {
      for (const r of [...(obj.resources ?? []), ...(obj.patches ?? []).map((p) => p.path)])
        if (!fs.existsSync(path.join(path.dirname(file), r))) fail(file, `refers to missing '${r}'`);
      for (const g of obj.secretGenerator ?? [])
        for (const f of g.files ?? [])
          if (!fs.existsSync(path.join(path.dirname(file), f))) fail(file, `secretGenerator file '${f}' missing`);
      checked++;
      continue;
    }
    const Model = models[obj.apiVersion]?.[obj.kind];
    if (!Model) {
      fail(file, `${obj.apiVersion} ${obj.kind}: not a kind this check knows`);
      continue;
    }
    // A strategic-merge patch is a partial object: it must name a kind and an object, and
    // what it sets is checked once merged into the base (here: against the base's kind).
    const isPatch = file.includes(`${path.sep}overlays${path.sep}`) && file.endsWith("-patch.yaml");
    const unknown = [];
    unknownFields(obj, modelName(obj), obj.kind, unknown);
    for (const u of unknown) fail(file, u);
    if (isPatch) {
      if (!obj.metadata?.name) fail(file, "patch without metadata.name");
      checked++;
      continue;
    }
    try {
      new Model(obj).validate();
      checked++;
    } catch (e) {
      fail(file, `${obj.kind} ${obj.metadata?.name}: ${e.message}`);
    }
  }
}
if (checked === 0) fail(root, "no manifests found");
console.log(`${checked} manifests checked, ${failures} problems`);
process.exit(failures ? 1 : 0);
