// Runs the Khronos glTF validator (npm gltf-validator, pinned in package.json) on each file.
//
//   node validate.mjs FILE.gltf|FILE.glb ...
//
// Prints one JSON line per file: {"file", "errors", "warnings", "infos", "hints", "messages": [the
// errors' and warnings' codes, pointers and texts]}. Exit 1 when the validator itself fails.
import { readFileSync } from 'node:fs';
import validator from 'gltf-validator';

async function main() {
  const files = process.argv.slice(2);
  if (files.length === 0) throw new Error('usage: validate.mjs FILE...');
  for (const file of files) {
    const report = await validator.validateBytes(new Uint8Array(readFileSync(file)), {
      maxIssues: 100,
      // A .gltf of ours embeds its buffer; nothing else is ever loaded.
      externalResourceFunction: (uri) => Promise.reject(new Error(`unexpected external resource ${uri}`)),
    });
    const issues = report.issues;
    const messages = issues.messages
      .filter((m) => m.severity <= 1)
      .map((m) => `${m.code} ${m.pointer ?? ''}: ${m.message}`);
    process.stdout.write(`${JSON.stringify({
      file,
      errors: issues.numErrors,
      warnings: issues.numWarnings,
      infos: issues.numInfos,
      hints: issues.numHints,
      messages,
    })}\n`);
  }
}

main().catch((error) => {
  process.stderr.write(`validate: ${error.stack || error}\n`);
  process.exit(1);
});
