// Validates .glb files with the Khronos glTF-Validator (npm: gltf-validator).
// Usage: node validate_gltf.mjs FILE.glb...   Exit 0 when every file has 0 errors.
import { readFileSync } from 'node:fs';
import { createRequire } from 'node:module';

const require = createRequire(process.cwd() + '/');
let validator;
try {
  validator = require('gltf-validator');
} catch (e) {
  console.error('gltf-validator is not installed (npm install gltf-validator; set NODE_PATH)');
  process.exit(2);
}
let failed = 0;
for (const file of process.argv.slice(2)) {
  const report = await validator.validateBytes(new Uint8Array(readFileSync(file)));
  const { numErrors, numWarnings } = report.issues;
  console.log(`${file}: ${numErrors} errors, ${numWarnings} warnings`);
  for (const m of report.issues.messages) {
    if (m.severity <= 1) console.log(`  ${m.severity === 0 ? 'error' : 'warning'} ${m.code}: ${m.message} ${m.pointer ?? ''}`);
  }
  if (numErrors > 0) failed++;
}
process.exit(failed ? 1 : 0);
