// Reads a glTF (.glb or .gltf) as two real consumers do and prints one JSON line:
//   validator: the Khronos glTF validator's issue counts and messages (gltf-validator);
//   three: what three.js's GLTFLoader makes of it: per mesh its vertex count and morph
//   target names, per animation its tracks (name, key times, values).
// Usage: node gltf_check.mjs FILE
import { readFileSync } from 'node:fs';
import { basename } from 'node:path';
import validator from 'gltf-validator';
import { GLTFLoader } from 'three/examples/jsm/loaders/GLTFLoader.js';

// GLTFLoader reads a .gltf's embedded data: URIs with fetch() and reports progress with the
// browser's ProgressEvent, which Node lacks: a minimal stand-in.
globalThis.ProgressEvent ??= class ProgressEvent extends Event {
  constructor(type, init = {}) {
    super(type);
    Object.assign(this, init);
  }
};

const file = process.argv[2];
const bytes = readFileSync(file);

const report = await validator.validateBytes(new Uint8Array(bytes), {
  uri: basename(file),
  maxIssues: 100,
  externalResourceFunction: () => Promise.reject(new Error('external resources are not expected')),
});

const arrayBuffer = bytes.buffer.slice(bytes.byteOffset, bytes.byteOffset + bytes.byteLength);
const gltf = await new Promise((resolve, reject) => new GLTFLoader().parse(arrayBuffer, '', resolve, reject));
const meshes = [];
gltf.scene.traverse((object) => {
  if (!object.isMesh && !object.isPoints) return;
  const names = Object.entries(object.morphTargetDictionary ?? {}).sort((a, b) => a[1] - b[1]).map(([name]) => name);
  meshes.push({ name: object.name, vertices: object.geometry.attributes.position.count, targetNames: names });
});
const animations = gltf.animations.map((clip) => ({
  name: clip.name,
  duration: clip.duration,
  tracks: clip.tracks.map((track) => ({
    name: track.name,
    times: Array.from(track.times),
    values: Array.from(track.values),
  })),
}));

console.log(JSON.stringify({
  validator: {
    errors: report.issues.numErrors,
    warnings: report.issues.numWarnings,
    infos: report.issues.numInfos,
    messages: report.issues.messages.filter((m) => m.severity <= 1),
  },
  three: { meshes, animations, extras: gltf.animations.length ? gltf.parser.json.animations[0].extras ?? {} : {} },
}));
