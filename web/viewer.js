// The page of `vmap view`: the points as round splats, orbit and walk, and the V-map's answers
// from the server (src/view/view_server.h has the endpoints). window.vmapView is for tests.
import * as THREE from 'three';
import {OrbitControls} from 'three/addons/OrbitControls.js';

const kVisible = [149, 39, 220];  // sRGB of render.h's VisibleStyle: purple
const kEye = [0, 238, 238];       // cyan
const kHiddenDim = 0.45;          // hidden points: albedo x this (in linear light)

const $ = (id) => document.getElementById(id);

// sRGB byte -> byte of the same colour dimmed in linear light (as visible_colors does).
const dimLut = new Uint8Array(256).map((_, c) => {
    const s = c / 255;
    const lin = s <= 0.04045 ? s / 12.92 : Math.pow((s + 0.055) / 1.055, 2.4);
    const d = lin * kHiddenDim;
    const o = d <= 0.0031308 ? 12.92 * d : 1.055 * Math.pow(d, 1 / 2.4) - 0.055;
    return Math.round(Math.min(1, Math.max(0, o)) * 255);
});

async function postJson(url, body) {
    const r = await fetch(url, {method: 'POST', body: JSON.stringify(body)});
    const j = await r.json();
    if (!r.ok) throw new Error(j.error || `${url}: status ${r.status}`);
    return j;
}

// The /api/points buffer: positions, normals, albedo, radii, GI colours (view_server.h).
function splitPoints(buf, n, hasGi) {
    let at = 0;
    const take = (Type, count) => {
        const a = new Type(buf, at, count);
        at += count * Type.BYTES_PER_ELEMENT;
        return a;
    };
    const positions = take(Float32Array, 3 * n);
    const normals = take(Float32Array, 3 * n);
    const albedo = take(Uint8Array, 3 * n);
    // The radii follow 3n bytes: copy to an aligned buffer when 3n is not a multiple of 4.
    const radii =
        (at % 4 === 0) ? take(Float32Array, n) : new Float32Array(buf.slice(at, (at += 4 * n)));
    const gi = hasGi ? take(Uint8Array, 3 * n) : null;
    return {positions, normals, albedo, radii, gi};
}

// A seeded random order of the points (Fisher-Yates, mulberry32): any prefix of it is a uniform
// sample of the cloud, whatever order the file had, so a moving view can draw a prefix.
// Returns order (slot -> id) and slot (id -> slot), and the arrays permuted into slot order.
function shuffled(pts, n) {
    let a = 0x9e3779b9;
    const rand = () => {
        a = (a + 0x6d2b79f5) | 0;
        let t = Math.imul(a ^ (a >>> 15), 1 | a);
        t = (t + Math.imul(t ^ (t >>> 7), 61 | t)) ^ t;
        return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
    };
    const order = new Uint32Array(n).map((_, i) => i);
    for (let i = n - 1; i > 0; --i) {
        const j = Math.floor(rand() * (i + 1));
        [order[i], order[j]] = [order[j], order[i]];
    }
    const slot = new Uint32Array(n);
    order.forEach((id, k) => {
        slot[id] = k;
    });
    const permute = (src, width) => {
        if (!src) return null;
        const out = new src.constructor(src.length);
        for (let k = 0; k < n; ++k)
            for (let c = 0; c < width; ++c) out[width * k + c] = src[width * order[k] + c];
        return out;
    };
    return {
        order,
        slot,
        positions: permute(pts.positions, 3),
        normals: permute(pts.normals, 3),
        albedo: permute(pts.albedo, 3),
        radii: permute(pts.radii, 1),
        gi: permute(pts.gi, 3)
    };
}

const vertexShader = `
attribute float radius;
attribute vec3 vcolor;
uniform float uScale;   // pixels per scene unit at distance 1
uniform float uSplat;   // splat radius multiplier (larger when only a prefix is drawn)
uniform float uShade;   // 1: shade by |n . view|
varying vec3 vColor;
void main() {
    vec4 mv = modelViewMatrix * vec4(position, 1.0);
    gl_Position = projectionMatrix * mv;
    gl_PointSize = clamp(2.0 * radius * uSplat * uScale / max(-mv.z, 1e-6), 1.5, 64.0);
    float s = abs(dot(normal, normalize(cameraPosition - position)));
    vColor = vcolor * mix(1.0, 0.25 + 0.75 * s, uShade);
}`;
const fragmentShader = `
varying vec3 vColor;
void main() {
    vec2 d = gl_PointCoord - vec2(0.5);
    if (dot(d, d) > 0.25) discard;
    gl_FragColor = vec4(vColor, 1.0);
}`;

class Viewer {
    constructor(info, pts) {
        this.info = info;
        this.n = info.points;
        this.pts = shuffled(pts, this.n);        // slot order; ids map through order and slot
        this.budget = Math.min(this.n, 100000);  // points drawn while the view moves (adapted)
        this.lastMove = 0;
        this.eye = -1;
        this.visible = null;
        this.size = Math.hypot(...info.bounds.max.map((v, i) => v - info.bounds.min[i]));
        this.renderer = new THREE.WebGLRenderer({canvas: $('view'), antialias: false});
        this.renderer.setPixelRatio(1);
        this.renderer.setClearColor(0x0b0b0e);
        this.scene = new THREE.Scene();
        this.initCamera();
        this.initPoints();
        this.markers = new THREE.Group();
        this.scene.add(this.markers);
        this.keys = new Set();
        this.walk = false;
        this.resize();
        this.bindEvents();
        this.setMode(info.gi ? 'gi' : 'shaded');
    }

    initCamera() {
        const c = this.info.camera;
        this.camera = new THREE.PerspectiveCamera(c.fov, 1, this.size * 1e-3, this.size * 20);
        this.controls = new OrbitControls(this.camera, this.renderer.domElement);
        this.home();
        this.controls.addEventListener('change', () => this.moved());
    }

    // The server's camera: the scene's, or the default view through the room's open side.
    home() {
        const c = this.info.camera;
        this.camera.position.fromArray(c.eye);
        this.camera.up.fromArray(c.up);
        this.controls.target.fromArray(c.target);
        this.walk = false;
        this.controls.update();
    }

    initPoints() {
        const g = new THREE.BufferGeometry();
        g.setAttribute('position', new THREE.BufferAttribute(this.pts.positions, 3));
        g.setAttribute('normal', new THREE.BufferAttribute(this.pts.normals, 3));
        const radii =
            this.info.radii ? this.pts.radii : new Float32Array(this.n).fill(this.size * 2e-3);
        g.setAttribute('radius', new THREE.BufferAttribute(radii, 1));
        this.colors = new Uint8Array(3 * this.n);
        this.colorAttr = new THREE.BufferAttribute(this.colors, 3, true);
        g.setAttribute('vcolor', this.colorAttr);
        this.material = new THREE.ShaderMaterial({
            uniforms: {uScale: {value: 1}, uSplat: {value: 2}, uShade: {value: 1}},
            vertexShader,
            fragmentShader,
        });
        this.splat = 2;
        this.points = new THREE.Points(g, this.material);
        this.points.frustumCulled = false;
        this.scene.add(this.points);
    }

    bindEvents() {
        window.addEventListener('resize', () => this.resize());
        $('mode').addEventListener('change', (e) => this.setMode(e.target.value));
        $('splat').addEventListener('input', (e) => {
            this.splat = Number(e.target.value);
            this.requestRender();
        });
        $('showLeaf').addEventListener('change', () => this.drawMarkers());
        const el = this.renderer.domElement;
        let down = null;
        el.addEventListener('pointerdown', (e) => {
            down = [e.clientX, e.clientY];
        });
        el.addEventListener('pointerup', (e) => {
            if (!down || e.button !== 0) return;
            const moved = Math.hypot(e.clientX - down[0], e.clientY - down[1]);
            down = null;
            if (moved < 4) this.onClick(e.clientX, e.clientY, e.shiftKey);
        });
        window.addEventListener('keydown', (e) => this.onKey(e, true));
        window.addEventListener('keyup', (e) => this.onKey(e, false));
    }

    resize() {
        const w = window.innerWidth, h = window.innerHeight;
        this.camera.aspect = w / h;
        this.camera.updateProjectionMatrix();
        const fov = THREE.MathUtils.degToRad(this.camera.fov);
        this.cssScale = h / (2 * Math.tan(fov / 2));  // CSS pixels per unit at distance 1
        this.ratio = 0;
        this.setResolution(1);
        this.requestRender();
    }

    // Draws at `ratio` of the CSS resolution (the canvas is stretched to the window).
    setResolution(ratio) {
        if (ratio === this.ratio) return;
        this.ratio = ratio;
        this.renderer.setPixelRatio(ratio);
        this.renderer.setSize(window.innerWidth, window.innerHeight, false);
        this.material.uniforms.uScale.value = this.cssScale * ratio;
    }

    requestRender() {
        if (this.pending) return;
        this.pending = true;
        requestAnimationFrame((t) => this.frame(t));
    }

    moved() {
        this.lastMove = performance.now();
        this.movedSinceFrame = true;
        this.requestRender();
    }

    // While the view moves, the picture is drawn at half resolution and only a prefix of the
    // shuffled points, with splats grown to cover the same area; the prefix follows the frame
    // time towards 30 frames a second. 150 ms after the last move the full cloud is drawn once
    // at full resolution.
    frame(now) {
        this.pending = false;
        if (this.keys.size) this.stepWalk();
        const moving = this.keys.size > 0 || this.movedSinceFrame || now - this.lastMove < 150;
        this.movedSinceFrame = false;
        if (moving && this.lastFrame) {
            const dt = now - this.lastFrame;
            if (dt > 40)
                this.budget = Math.max(10000, this.budget * 0.8);
            else if (dt < 28)
                this.budget = Math.min(this.n, this.budget * 1.15);
        }
        const m = moving ? Math.min(this.n, Math.round(this.budget)) : this.n;
        this.setResolution(moving ? 0.5 : 1);
        this.drawPrefix(m);
        this.renderer.render(this.scene, this.camera);
        this.frames = (this.frames || 0) + 1;
        this.lastFrame = moving ? now : 0;
        if (moving) this.requestRender();
    }

    drawPrefix(m) {
        this.points.geometry.setDrawRange(0, m);
        this.material.uniforms.uSplat.value = this.splat * Math.sqrt(this.n / m);
        this.drawn = m;
    }

    setMode(mode) {
        if (mode === 'gi' && !this.pts.gi) mode = 'shaded';
        this.mode = mode;
        $('mode').value = mode;
        this.material.uniforms.uShade.value = mode === 'shaded' ? 1 : 0;
        this.updateColors();
    }

    baseColors() {
        return this.mode === 'gi' ? this.pts.gi : this.pts.albedo;
    }

    // Colours of every point: the base colour, or Fig. 9's when an eye is set.
    updateColors() {
        const base = this.baseColors(), c = this.colors;
        if (!this.visible) {
            c.set(base);
        } else {
            for (let i = 0; i < c.length; ++i) c[i] = dimLut[base[i]];
            const slot = this.pts.slot, bits = this.visible.mask;
            for (let b = 0; b < bits.length; ++b) {
                if (!bits[b]) continue;
                for (let k = 0; k < 8; ++k)
                    if (bits[b] & (1 << k)) c.set(kVisible, 3 * slot[8 * b + k]);
            }
            for (const id of this.visible.leaf_ids) c.set(kEye, 3 * slot[id]);
        }
        this.colorAttr.needsUpdate = true;
        this.requestRender();
    }

    position(id) {
        return new THREE.Vector3().fromArray(this.pts.positions, 3 * this.pts.slot[id]);
    }

    // Where point `id` lands on the canvas, in CSS pixels, and its depth (null: behind).
    screenOf(id) {
        const p = this.position(id).project(this.camera);
        if (p.z < -1 || p.z > 1) return null;
        const r = this.renderer.domElement.getBoundingClientRect();
        return {x: r.left + (p.x + 1) / 2 * r.width, y: r.top + (1 - p.y) / 2 * r.height, z: p.z};
    }

    // The point under a canvas position: of the points whose splat covers it (at least 4 px),
    // those within 1% of the nearest depth, the one nearest on screen.
    pickAt(cx, cy) {
        const r = this.renderer.domElement.getBoundingClientRect();
        const m =
            new THREE.Matrix4()
                .multiplyMatrices(this.camera.projectionMatrix, this.camera.matrixWorldInverse)
                .elements;
        const P = this.pts.positions, R = this.points.geometry.attributes.radius.array;
        const k = this.cssScale * this.splat;
        const cand = [];
        for (let i = 0; i < this.n; ++i) {
            const x = P[3 * i], y = P[3 * i + 1], z = P[3 * i + 2];
            const w = m[3] * x + m[7] * y + m[11] * z + m[15];
            if (w <= 0) continue;
            const sx = r.left + ((m[0] * x + m[4] * y + m[8] * z + m[12]) / w + 1) / 2 * r.width;
            const sy = r.top + (1 - (m[1] * x + m[5] * y + m[9] * z + m[13]) / w) / 2 * r.height;
            const d2 = (sx - cx) ** 2 + (sy - cy) ** 2;
            const rad = Math.max(4, R[i] * k / w);
            if (d2 <= rad * rad) cand.push([w, d2, i]);
        }
        if (!cand.length) return -1;
        const near = Math.min(...cand.map((c) => c[0])) * 1.01;
        let best = null;
        for (const c of cand)
            if (c[0] <= near && (!best || c[1] < best[1])) best = c;
        return this.pts.order[best[2]];
    }

    async onClick(cx, cy, shift) {
        const t0 = performance.now();
        const id = this.pickAt(cx, cy);
        if (id < 0) return;
        await this.report(shift && this.eye >= 0 ? this.queryPair(id) : this.setEye(id, t0));
    }

    // Shows a failed request (server gone, or its 400 message) in the panel.
    async report(promise) {
        try {
            return await promise;
        } catch (e) {
            $('timing').textContent = `error: ${e.message}`;
            return null;
        }
    }

    async setEye(id, t0 = performance.now()) {
        const tPick = performance.now();
        const v = await postJson('api/visible', {id, as: 'bits'});
        v.mask = Uint8Array.from(atob(v.bits), (ch) => ch.charCodeAt(0));
        const tFetch = performance.now();
        this.eye = id;
        this.visible = v;
        this.pair = null;
        this.ray = null;
        this.updateColors();
        this.drawMarkers();
        this.renderer.render(this.scene, this.camera);
        const tDraw = performance.now();
        // Benchmarks wait for the frame to be finished (a one-pixel read), the page does not.
        if (window.vmapView.finishFrames) this.finish();
        const t1 = performance.now();
        this.latency = {
            total: t1 - t0,
            pick: tPick - t0,
            fetch: tFetch - tPick,
            server: v.server_ms,
            draw: tDraw - tFetch,
            finish: t1 - tDraw
        };
        $('eye').textContent = `#${id}`;
        $('count').textContent = `${v.count} of ${this.n} points`;
        $('leaf').textContent = `leaf ${v.leaf} at level ${v.level} (octree height ${v.height}), ` +
            `${v.leaf_ids.length} points`;
        $('pair').textContent = 'shift-click a second point';
        $('ray').textContent = 'press R';
        $('timing').textContent = `click to picture ${this.latency.total.toFixed(1)} ms ` +
            `(server ${v.server_ms.toFixed(1)} ms)`;
        document.body.dataset.eye = id;
        document.body.dataset.count = v.count;
        return v;
    }

    async queryPair(id) {
        const r = await postJson('api/pair', {a: this.eye, b: id});
        this.pair = {id, result: r.result};
        $('pair').textContent = `#${this.eye} and #${id}: ${r.result}`;
        document.body.dataset.pair = r.result;
        this.drawMarkers();
        return r;
    }

    async shootRay() {
        if (this.eye < 0) return null;
        const dir = new THREE.Vector3();
        this.camera.getWorldDirection(dir);
        const r = await postJson('api/ray', {id: this.eye, dir: dir.toArray()});
        this.ray = {dir, hit: r.hit ? r : null};
        $('ray').textContent =
            r.hit ? `hits #${r.hit_id} at ${r.distance.toPrecision(3)}` : 'no hit';
        document.body.dataset.ray = r.hit ? r.hit_id : 'none';
        this.drawMarkers();
        return r;
    }

    // Markers are drawn over the points (no depth test), so a ray inside the model still shows.
    sphere(p, color, scale = 1) {
        const s = new THREE.Mesh(
            new THREE.SphereGeometry(this.size * 0.008 * scale, 12, 8),
            new THREE.MeshBasicMaterial({color, depthTest: false}));
        s.position.copy(p);
        s.renderOrder = 2;
        this.markers.add(s);
    }

    line(a, b, color) {
        const g = new THREE.BufferGeometry().setFromPoints([a, b]);
        const l = new THREE.Line(g, new THREE.LineBasicMaterial({color, depthTest: false}));
        l.renderOrder = 1;
        this.markers.add(l);
    }

    // The eye (cyan), its leaf cell, the pair's second point and line, the ray and its hit.
    drawMarkers() {
        this.markers.clear();
        if (this.eye < 0) return this.requestRender();
        const e = this.position(this.eye);
        this.sphere(e, 0x00eeee);
        if ($('showLeaf').checked) {
            const c = new THREE.Vector3().fromArray(this.visible.cell.center);
            const h = this.visible.cell.half;
            const box = new THREE.Box3(c.clone().subScalar(h), c.clone().addScalar(h));
            this.markers.add(new THREE.Box3Helper(box, 0xffffff));
        }
        if (this.pair) {
            const q = this.position(this.pair.id);
            this.sphere(q, 0xff9900);
            this.line(e, q, this.pair.result === 'visible' ? 0x33dd55 : 0xee3333);
        }
        if (this.ray) {
            const end = this.ray.hit ? new THREE.Vector3().fromArray(this.ray.hit.point) :
                                       e.clone().addScaledVector(this.ray.dir, this.size);
            this.line(e, end, 0xffee00);
            if (this.ray.hit) this.sphere(end, 0xffee00, 0.8);
        }
        this.requestRender();
    }

    clear() {
        this.eye = -1;
        this.visible = this.pair = this.ray = null;
        $('eye').textContent = 'none: click a point';
        $('count').textContent = $('leaf').textContent = '\u2013';
        this.updateColors();
        this.drawMarkers();
    }

    onKey(e, down) {
        const k = e.key.toLowerCase();
        if (down && k === 'r') return void this.report(this.shootRay());
        if (down && k === 'escape') return this.clear();
        if (down && k === 'f') return this.toggleWalk();
        if (down && k === 'h') return this.home();
        if (!'wasdqe'.includes(k) || k.length !== 1) return;
        if (down)
            this.keys.add(k);
        else
            this.keys.delete(k);
        this.requestRender();
    }

    // Walk mode: the orbit centre just in front of the eye, so a drag looks around.
    toggleWalk() {
        this.walk = !this.walk;
        const dir = new THREE.Vector3();
        this.camera.getWorldDirection(dir);
        const dist = this.walk ? this.size * 0.02 : this.size * 0.5;
        this.controls.target.copy(this.camera.position).addScaledVector(dir, dist);
        this.controls.update();
    }

    stepWalk() {
        const f = new THREE.Vector3(), s = new THREE.Vector3();
        this.camera.getWorldDirection(f);
        s.crossVectors(f, this.camera.up).normalize();
        const v = new THREE.Vector3(), step = this.size * 0.004;
        if (this.keys.has('w')) v.add(f);
        if (this.keys.has('s')) v.sub(f);
        if (this.keys.has('d')) v.add(s);
        if (this.keys.has('a')) v.sub(s);
        if (this.keys.has('e')) v.add(this.camera.up);
        if (this.keys.has('q')) v.sub(this.camera.up);
        v.multiplyScalar(step);
        this.camera.position.add(v);
        this.controls.target.add(v);
        this.controls.update();
    }

    // Turns the camera about the vertical through the orbit centre by `angle` radians.
    orbitStep(angle) {
        const t = this.controls.target;
        this.camera.position.sub(t).applyAxisAngle(this.camera.up, angle).add(t);
        this.controls.update();
    }

    // Waits until the GPU (or SwiftShader) has drawn what was submitted: a one-pixel read.
    finish() {
        const gl = this.renderer.getContext();
        gl.readPixels(0, 0, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, new Uint8Array(4));
    }

    // For benchmarks: draw `frames` frames, each finished, while the camera orbits; milliseconds
    // per frame.
    timeFrames(frames) {
        this.setResolution(1);
        this.drawPrefix(this.n);
        const times = [];
        for (let f = 0; f < frames; ++f) {
            const t0 = performance.now();
            this.orbitStep((2 * Math.PI) / frames);
            this.renderer.render(this.scene, this.camera);
            this.finish();
            times.push(performance.now() - t0);
        }
        return times;
    }
}

async function main() {
    const info = await (await fetch('api/info')).json();
    const buf = await (await fetch('api/points')).arrayBuffer();
    const pts = splitPoints(buf, info.points, info.gi);
    $('mode').querySelector('[value=gi]').disabled = !info.gi;
    $('scene').textContent = `${info.name}: ${info.points} points, ${info.leaves} leaves, ` +
        `octree height ${info.height}, ${info.links} links`;
    const v = new Viewer(info, pts);
    window.vmapView.viewer = v;
    window.vmapView.ready = true;
    document.body.dataset.ready = '1';
}

window.vmapView = {
    ready: false
};
main().catch((e) => {
    $('scene').textContent = `error: ${e.message}`;
    window.vmapView.error = e.message;
});
