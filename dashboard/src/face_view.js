// The 3D view of a solved face, shared by the live and replay pages: the mesh from the
// stream's schema (triangles once) and frames (vertices), the captured markers drawn over
// it coloured by their fit residual, missing and gated markers drawn apart, and the head
// pose the stabilisation removed as a small set of axes.
import * as THREE from 'three';
import { OrbitControls } from 'three/examples/jsm/controls/OrbitControls.js';

// Residuals at or above this many millimetres are drawn fully red.
const kResidualRedMm = 2.0;
const kMissingColour = new THREE.Color(0x7a8290);
const kGatedColour = new THREE.Color(0xd040e0);
// Calibrated markers the source has no slot for, drawn at their calibrated place.
const kUnslottedMarkers = 256;

// Green (0 mm) through yellow to red (kResidualRedMm and above).
function residualColour(mm, out = new THREE.Color()) {
  const t = Math.min(1, Math.max(0, mm / kResidualRedMm));
  return out.setHSL((1 - t) * 0.33, 0.9, 0.5);
}

export class FaceView {
  constructor(canvas) {
    this.canvas = canvas;
    // preserveDrawingBuffer: the page's own pixel checks (and the browser test) read it.
    this.renderer = new THREE.WebGLRenderer({ canvas, antialias: true, preserveDrawingBuffer: true });
    this.renderer.setPixelRatio(Math.min(window.devicePixelRatio, 2));
    this.scene = new THREE.Scene();
    this.scene.background = new THREE.Color(0x15181d);
    this.camera = new THREE.PerspectiveCamera(30, 1, 0.01, 1e5);
    this.controls = new OrbitControls(this.camera, canvas);
    this.scene.add(new THREE.HemisphereLight(0xffffff, 0x404050, 2.2));
    const key = new THREE.DirectionalLight(0xffffff, 1.6);
    key.position.set(1, 1.5, 2);
    this.scene.add(key);
    this.mesh = null;
    this.markers = null;
    this.headAxes = new THREE.AxesHelper(1);
    this.scene.add(this.headAxes);
    this.markerCount = 0;
    this.lastTargets = [];  // per marker slot: last known [x, y, z], for drawing missing ones
    this.slotLabels = [];   // per marker slot: its label (the schema's)
    this.calibrated = [];   // the calibration's face markers from /status: label, rest [x, y, z], missing
    this.framed = false;
    this.colour = new THREE.Color();
    this.matrix = new THREE.Matrix4();
    new ResizeObserver(() => this.resize()).observe(canvas);
    this.resize();
    const loop = () => {
      this.controls.update();
      this.renderer.render(this.scene, this.camera);
      requestAnimationFrame(loop);
    };
    requestAnimationFrame(loop);
  }

  resize() {
    const width = this.canvas.clientWidth || 1, height = this.canvas.clientHeight || 1;
    this.renderer.setSize(width, height, false);
    this.camera.aspect = width / height;
    this.camera.updateProjectionMatrix();
  }

  // A stream schema message: builds the mesh (when it has triangles) and the marker slots.
  setSchema(schema) {
    if (this.mesh) {
      this.scene.remove(this.mesh);
      this.mesh.geometry.dispose();
      this.mesh = null;
    }
    if (this.markers) {
      this.scene.remove(this.markers);
      this.markers = null;
    }
    this.framed = false;
    if (schema.vertex_count > 0 && schema.triangles) {
      const geometry = new THREE.BufferGeometry();
      geometry.setAttribute('position', new THREE.BufferAttribute(new Float32Array(schema.vertex_count * 3), 3));
      geometry.setIndex(schema.triangles);
      const material = new THREE.MeshStandardMaterial({
        color: 0xc8b4a0, roughness: 0.7, metalness: 0.0, side: THREE.DoubleSide,
        transparent: true, opacity: 0.92,
      });
      this.mesh = new THREE.Mesh(geometry, material);
      this.scene.add(this.mesh);
    }
    this.markerCount = schema.markers.length;
    this.slotLabels = schema.markers;
    this.lastTargets = new Array(this.markerCount).fill(null);
    if (this.markerCount > 0) {
      const sphere = new THREE.SphereGeometry(1, 10, 8);
      const material = new THREE.MeshBasicMaterial({ depthTest: false, transparent: true, opacity: 0.95 });
      // Room for calibrated markers the source has no slot for (never seen).
      this.markers = new THREE.InstancedMesh(sphere, material, this.markerCount + kUnslottedMarkers);
      this.markers.renderOrder = 1;  // over the surface, so markers behind it still show
      this.markers.count = 0;
      this.scene.add(this.markers);
    }
  }

  // A frame message: the mesh, the markers and the head pose. Returns the number of
  // vertices drawn (0 when the frame carried none).
  update(frame) {
    let drawn = 0;
    if (this.mesh && frame.vertices && frame.vertices.length === this.mesh.geometry.attributes.position.count * 3) {
      const position = this.mesh.geometry.attributes.position;
      position.array.set(frame.vertices);
      position.needsUpdate = true;
      this.mesh.geometry.computeVertexNormals();
      this.mesh.geometry.computeBoundingSphere();
      drawn = position.count;
      if (!this.framed) this.frame(this.mesh.geometry.boundingSphere);
    }
    this.updateMarkers(frame.markers);
    this.updateHead(frame.head);
    return drawn;
  }

  frame(sphere) {
    this.framed = true;
    const r = sphere.radius || 1;
    this.radius = r;
    this.controls.target.copy(sphere.center);
    this.camera.position.copy(sphere.center).add(new THREE.Vector3(0, 0, r * 4.2));
    this.camera.near = r * 0.01;
    this.camera.far = r * 100;
    this.camera.updateProjectionMatrix();
    this.headAxes.scale.setScalar(r * 0.35);
    this.headAxes.position.copy(sphere.center).add(new THREE.Vector3(r * 0.95, -r * 0.75, 0));
  }

  // The calibration's face markers (GET /status window.markers): where a marker never seen
  // is drawn (its bound point on the neutral face), and which ones the quality counts missing.
  setCalibratedMarkers(markers) {
    this.calibrated = markers ?? [];
  }

  // Markers: used ones coloured by residual; missing ones (absent this frame) grey at their
  // last place, or at their calibrated place when never seen (also those the source has no
  // slot for); gated ones (present but not used: not bound, or left out as implausible)
  // magenta and larger.
  updateMarkers(markers) {
    if (!this.markers || !markers) return;
    const size = (this.radius ?? 10) * 0.018;
    const rest = new Map(this.calibrated.map((m) => [m.label, m.rest]));
    let n = 0;
    for (let k = 0; k < this.markerCount; ++k) {
      const target = markers.targets[k];
      if (target) this.lastTargets[k] = target;
      const at = target ?? this.lastTargets[k] ?? rest.get(this.slotLabels[k]);
      if (!at) continue;
      let scale = size;
      if (target && markers.residual_mm[k] !== null) {
        residualColour(markers.residual_mm[k], this.colour);
      } else if (markers.present[k]) {
        this.colour.copy(kGatedColour);
        scale = size * 1.4;
      } else {
        this.colour.copy(kMissingColour);
        scale = size * 0.7;
      }
      this.matrix.makeScale(scale, scale, scale).setPosition(at[0], at[1], at[2]);
      this.markers.setMatrixAt(n, this.matrix);
      this.markers.setColorAt(n, this.colour);
      ++n;
    }
    const slotted = new Set(this.slotLabels);
    for (const m of this.calibrated) {
      if (slotted.has(m.label) || n >= this.markerCount + kUnslottedMarkers) continue;
      const s = size * 0.7;
      this.matrix.makeScale(s, s, s).setPosition(m.rest[0], m.rest[1], m.rest[2]);
      this.markers.setMatrixAt(n, this.matrix);
      this.markers.setColorAt(n, kMissingColour);
      ++n;
    }
    this.markers.count = n;
    this.markers.instanceMatrix.needsUpdate = true;
    if (this.markers.instanceColor) this.markers.instanceColor.needsUpdate = true;
  }

  updateHead(head) {
    if (!head) return;
    const [w, x, y, z] = head.rotation_wxyz;
    this.headAxes.quaternion.set(x, y, z, w);
  }
}

// Yaw, pitch and roll in degrees (Y up, as the rig's frame) of a [w, x, y, z] rotation.
export function yawPitchRoll([w, x, y, z]) {
  const euler = new THREE.Euler().setFromQuaternion(new THREE.Quaternion(x, y, z, w), 'YXZ');
  return [euler.y, euler.x, euler.z].map((a) => THREE.MathUtils.radToDeg(a));
}
