// The 3D view of a run: the platform's MuJoCo model (from /api/scene) drawn with three.js,
// posed per sample, with the reference and actual paths on the floor. World z is up.
// Renders only on demand (requestRender), at most once per animation frame.
import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';

const PATH_Z = 0.003;                      // paths slightly above the floor [m]
const FLOOR_DEFAULT = [[0.34, 0.37, 0.41], [0.24, 0.26, 0.30]];   // omnitwin's MJCF checker
const CAMERA_OFFSET = new THREE.Vector3(1.1, -1.5, 1.05);         // from the platform, like MJCF "overview"

// MuJoCo quaternion [w, x, y, z] -> three.js
function mjQuat(q) {
  if (!Array.isArray(q) || q.length !== 4) return new THREE.Quaternion();
  return new THREE.Quaternion(q[1], q[2], q[3], q[0]).normalize();
}
const finite = (v) => typeof v === 'number' && Number.isFinite(v);
function vec3(a, d = [0, 0, 0]) { return Array.isArray(a) && a.length >= 3 ? a.map(Number) : d; }

function checkerTexture(c1, c2, line) {
  const n = 128;
  const cv = document.createElement('canvas');
  cv.width = cv.height = n;
  const g = cv.getContext('2d');
  const css = (c) => `rgb(${Math.round(c[0] * 255)},${Math.round(c[1] * 255)},${Math.round(c[2] * 255)})`;
  g.fillStyle = css(c1); g.fillRect(0, 0, n, n);
  g.fillStyle = css(c2); g.fillRect(0, 0, n / 2, n / 2); g.fillRect(n / 2, n / 2, n / 2, n / 2);
  g.strokeStyle = css(line); g.lineWidth = 1.5;
  g.strokeRect(0.75, 0.75, n - 1.5, n - 1.5);
  g.beginPath(); g.moveTo(n / 2, 0); g.lineTo(n / 2, n); g.moveTo(0, n / 2); g.lineTo(n, n / 2); g.stroke();
  const tex = new THREE.CanvasTexture(cv);
  tex.wrapS = tex.wrapT = THREE.RepeatWrapping;
  tex.colorSpace = THREE.SRGBColorSpace;
  return tex;
}

// A growing polyline (positions reallocated by doubling).
class PathLine {
  constructor(color, z) {
    this.z = z;
    this.n = 0;
    this.capacity = 0;
    this.geometry = new THREE.BufferGeometry();
    this.line = new THREE.Line(this.geometry, new THREE.LineBasicMaterial({ color, transparent: true, opacity: 0.95 }));
    this.line.frustumCulled = false;
    this.line.renderOrder = 1;
    this.reserve(1024);
  }
  reserve(cap) {
    if (cap <= this.capacity) return;
    const arr = new Float32Array(cap * 3);
    if (this.attr) arr.set(this.attr.array.subarray(0, this.n * 3));
    this.attr = new THREE.BufferAttribute(arr, 3);
    this.attr.setUsage(THREE.DynamicDrawUsage);
    this.geometry.setAttribute('position', this.attr);
    this.capacity = cap;
  }
  clear() { this.n = 0; this.geometry.setDrawRange(0, 0); }
  push(x, y) {
    if (!finite(x) || !finite(y)) return;
    if (this.n >= this.capacity) this.reserve(this.capacity * 2);
    const a = this.attr.array;
    const i = this.n * 3;
    a[i] = x; a[i + 1] = y; a[i + 2] = this.z;
    this.n++;
  }
  commit() {
    this.attr.needsUpdate = true;
    this.geometry.setDrawRange(0, this.n);
  }
}

export class Scene3D {
  // container: the element to fill; scene: the /api/scene object.
  constructor(container, scene) {
    this.container = container;
    this.frames = 0;
    this.follow = true;
    this._raf = 0;
    this.pathCount = 0;
    this.pathSource = null;

    const renderer = new THREE.WebGLRenderer({ antialias: true });
    renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
    renderer.outputColorSpace = THREE.SRGBColorSpace;
    container.prepend(renderer.domElement);
    this.renderer = renderer;

    const world = new THREE.Scene();
    world.background = new THREE.Color(0x1b1f27);
    world.fog = new THREE.Fog(0x1b1f27, 12, 45);
    this.world = world;
    const hemi = new THREE.HemisphereLight(0xdde8ff, 0x383c44, 1.8);
    hemi.position.set(0, 0, 1);
    world.add(hemi);
    const sun = new THREE.DirectionalLight(0xffffff, 1.6);
    sun.position.set(3, 2, 6);
    world.add(sun);

    const camera = new THREE.PerspectiveCamera(45, 1, 0.01, 200);
    camera.up.set(0, 0, 1);
    this.camera = camera;

    this._build(scene || { bodies: [], geoms: [] });

    this.paths = { ref: new PathLine(0xffb74d, PATH_Z), act: new PathLine(0x4fc3f7, PATH_Z + 0.001) };
    world.add(this.paths.ref.line, this.paths.act.line);
    this.refMarker = this._makeRefMarker();
    world.add(this.refMarker);

    const target = this.base ? this.base.group.position.clone() : new THREE.Vector3(0, 0, 0);
    camera.position.copy(target).add(CAMERA_OFFSET);
    const controls = new OrbitControls(camera, renderer.domElement);
    controls.target.copy(target);
    controls.maxPolarAngle = Math.PI * 0.495;
    controls.minDistance = 0.2;
    controls.maxDistance = 40;
    controls.update();
    controls.addEventListener('change', () => this.requestRender());
    this.controls = controls;

    this._resize();
    this._ro = new ResizeObserver(() => this._resize());
    this._ro.observe(container);
  }

  _build(scene) {
    const bodies = Array.isArray(scene.bodies) ? scene.bodies : [];
    const geoms = Array.isArray(scene.geoms) ? scene.geoms : [];
    this.baseZ = finite(scene.base_z) ? scene.base_z : null;
    const root = new THREE.Group();
    root.name = 'model';
    this.world.add(root);
    // one node per body: the body frame, and inside it the joint's frame (hinge rotation)
    const nodes = bodies.map((b, i) => {
      if (i === 0 || b.parent == null || b.parent < 0) return { group: root, inner: root, world: true };
      const group = new THREE.Group();
      group.name = b.name || `body${i}`;
      group.position.fromArray(vec3(b.pos));
      group.quaternion.copy(mjQuat(b.quat));
      let inner = group;
      const j = b.joint;
      if (j && j.type === 'hinge') {
        inner = new THREE.Group();
        inner.name = `${group.name}:hinge`;
        group.add(inner);
      }
      return { group, inner, joint: j || null };
    });
    nodes.forEach((n, i) => {
      if (n.world) return;
      const p = nodes[bodies[i].parent] || nodes[0];
      (p ? p.inner : root).add(n.group);
    });
    if (!nodes.length) nodes.push({ group: root, inner: root, world: true });

    this.base = null;
    this.wheels = [null, null, null, null];
    nodes.forEach((n) => {
      const role = n.joint && n.joint.role;
      if (role === 'base') this.base = n;
      const m = /^wheel([1-4])$/.exec(role || '');
      if (m && n.joint.type === 'hinge') {
        const axis = new THREE.Vector3().fromArray(vec3(n.joint.axis, [1, 0, 0]));
        if (axis.lengthSq() < 1e-12) axis.set(1, 0, 0);
        n.axis = axis.normalize();
        this.wheels[Number(m[1]) - 1] = n;
      }
    });
    if (this.base && this.baseZ == null) this.baseZ = this.base.group.position.z;

    const geomCache = new Map();
    const matCache = new Map();
    const material = (rgba) => {
      const key = rgba.join(',');
      let m = matCache.get(key);
      if (!m) {
        const c = new THREE.Color().setRGB(rgba[0], rgba[1], rgba[2], THREE.SRGBColorSpace);
        m = new THREE.MeshStandardMaterial({ color: c, roughness: 0.62, metalness: 0.08 });
        if (rgba[3] < 1) { m.transparent = true; m.opacity = rgba[3]; m.depthWrite = false; }
        matCache.set(key, m);
      }
      return m;
    };
    this.skipped = 0;
    this.meshes = 0;
    for (const g of geoms) {
      const rgba = Array.isArray(g.rgba) && g.rgba.length >= 3 ? [g.rgba[0], g.rgba[1], g.rgba[2], g.rgba[3] ?? 1] : [0.5, 0.5, 0.5, 1];
      if (!(rgba[3] > 0) || (finite(g.group) && g.group >= 3)) { this.skipped++; continue; }
      const node = nodes[g.body] || nodes[0];
      const s = vec3(g.size, [0.05, 0.05, 0.05]);
      let obj = null;
      if (g.type === 'plane') {
        obj = this._floor(s, rgba);
      } else {
        const key = `${g.type}:${s.join(',')}`;
        let geo = geomCache.get(key);
        if (!geo) {
          geo = this._geometry(g.type, s);
          if (geo) geomCache.set(key, geo);
        }
        if (geo) {
          obj = new THREE.Mesh(geo, material(rgba));
          if (g.type === 'ellipsoid') obj.scale.set(s[0], s[1], s[2]);
        }
      }
      if (!obj) { this.skipped++; continue; }
      obj.name = g.name || '';
      obj.position.fromArray(vec3(g.pos));
      obj.quaternion.copy(mjQuat(g.quat));
      node.inner.add(obj);
      this.meshes++;
    }
    if (!geoms.some((g) => g.type === 'plane')) root.add(this._floor([0, 0, 0], [1, 1, 1, 1]));
    const axes = new THREE.AxesHelper(0.25);
    axes.position.z = 0.004;
    root.add(axes);
  }

  _geometry(type, s) {
    switch (type) {
      case 'box': return new THREE.BoxGeometry(2 * s[0], 2 * s[1], 2 * s[2]);
      case 'sphere': return new THREE.SphereGeometry(s[0], 24, 16);
      case 'ellipsoid': return new THREE.SphereGeometry(1, 24, 16);
      // MuJoCo: axis along local z, size = radius, half-length; three.js: along y
      case 'cylinder': return new THREE.CylinderGeometry(s[0], s[0], 2 * s[1], 24).rotateX(Math.PI / 2);
      case 'capsule': return new THREE.CapsuleGeometry(s[0], 2 * s[1], 4, 12).rotateX(Math.PI / 2);
      default: return null;           // mesh (no vertex data in /api/scene), hfield, sdf
    }
  }

  _floor(s, rgba) {
    const w = s[0] > 0 ? 2 * s[0] : 60;
    const h = s[1] > 0 ? 2 * s[1] : 60;
    const lum = 0.2126 * rgba[0] + 0.7152 * rgba[1] + 0.0722 * rgba[2];
    let c1, c2;
    if (lum > 0.8) [c1, c2] = FLOOR_DEFAULT;     // material with a texture, no colour of its own
    else { c1 = rgba.slice(0, 3); c2 = c1.map((v) => v * 0.72); }
    const line = c1.map((v) => Math.min(1, v * 1.25 + 0.04));
    const tex = checkerTexture(c1, c2, line);
    const cell = 0.5;                           // one texture repeat: 2 × 2 squares of 0.25 m
    tex.repeat.set(w / cell, h / cell);
    tex.anisotropy = this.renderer.capabilities.getMaxAnisotropy();
    const mat = new THREE.MeshStandardMaterial({ map: tex, roughness: 0.95, metalness: 0 });
    const mesh = new THREE.Mesh(new THREE.PlaneGeometry(w, h), mat);
    mesh.renderOrder = 0;
    return mesh;
  }

  _makeRefMarker() {
    const g = new THREE.Group();
    const mat = new THREE.MeshBasicMaterial({ color: 0xffb74d, transparent: true, opacity: 0.85, side: THREE.DoubleSide, depthWrite: false });
    const ring = new THREE.Mesh(new THREE.RingGeometry(0.205, 0.222, 48), mat);
    const tick = new THREE.Mesh(new THREE.PlaneGeometry(0.09, 0.016).translate(0.265, 0, 0), mat);
    g.add(ring, tick);
    g.position.z = PATH_Z + 0.002;
    g.visible = false;
    g.renderOrder = 2;
    return g;
  }

  // Pose the model at sample s (x, y, phi, ref_*, wheels[].angle); nulls keep the last value.
  setSample(s) {
    if (!s) return;
    if (this.base) {
      const p = this.base.group.position;
      if (finite(s.x)) p.x = s.x;
      if (finite(s.y)) p.y = s.y;
      if (this.baseZ != null) p.z = this.baseZ;
      if (finite(s.phi)) this.base.group.quaternion.setFromAxisAngle(new THREE.Vector3(0, 0, 1), s.phi);
      if (this.follow) this._followTo(p);
    }
    const wheels = Array.isArray(s.wheels) ? s.wheels : [];
    this.wheels.forEach((n, i) => {
      const a = wheels[i] && wheels[i].angle;
      if (n && finite(a)) n.inner.quaternion.setFromAxisAngle(n.axis, a);
    });
    if (finite(s.ref_x) && finite(s.ref_y)) {
      this.refMarker.visible = true;
      this.refMarker.position.x = s.ref_x;
      this.refMarker.position.y = s.ref_y;
      this.refMarker.rotation.z = finite(s.ref_phi) ? s.ref_phi : 0;
    }
    this.requestRender();
  }

  _followTo(p) {
    const t = this.controls.target;
    const dx = p.x - t.x, dy = p.y - t.y, dz = p.z - t.z;
    if (dx === 0 && dy === 0 && dz === 0) return;
    this.camera.position.x += dx; this.camera.position.y += dy; this.camera.position.z += dz;
    t.set(p.x, p.y, p.z);
    this.controls.update();
  }

  setFollow(on) {
    this.follow = !!on;
    if (on && this.base) { this._followTo(this.base.group.position); this.requestRender(); }
  }

  // The paths of samples[0..count): appended incrementally when the same array grows.
  setPaths(samples, count = samples.length) {
    if (samples !== this.pathSource || count < this.pathCount) {
      this.paths.ref.clear(); this.paths.act.clear();
      this.pathSource = samples; this.pathCount = 0;
    }
    if (count === this.pathCount) return;
    for (let i = this.pathCount; i < count; i++) {
      const s = samples[i];
      this.paths.ref.push(s.ref_x, s.ref_y);
      this.paths.act.push(s.x, s.y);
    }
    this.pathCount = count;
    this.paths.ref.commit(); this.paths.act.commit();
    this.requestRender();
  }

  // One frame now with everything drawn (the reference marker and the paths too, which show
  // nothing yet): the driver compiles a shader when it is first drawn, which is slow in
  // software WebGL and must not happen when the first data arrive.
  renderNow() {
    const markerShown = this.refMarker ? this.refMarker.visible : false;
    if (this.refMarker) this.refMarker.visible = true;
    const paths = Object.values(this.paths || {});
    for (const p of paths) p.geometry.setDrawRange(0, 2);
    this.renderer.render(this.world, this.camera);
    for (const p of paths) p.geometry.setDrawRange(0, p.n);
    if (this.refMarker) this.refMarker.visible = markerShown;
    this.renderer.render(this.world, this.camera);
    this.frames++;
  }

  requestRender() {
    if (this._raf) return;
    this._raf = requestAnimationFrame(() => {
      this._raf = 0;
      this.renderer.render(this.world, this.camera);
      this.frames++;
    });
  }

  _resize() {
    const w = Math.max(1, this.container.clientWidth);
    const h = Math.max(1, this.container.clientHeight);
    this.renderer.setSize(w, h, false);
    this.camera.aspect = w / h;
    this.camera.updateProjectionMatrix();
    this.requestRender();
  }
}
