// How responsive `vmap view` is, in headless chromium with its GPU off (SwiftShader WebGL):
//   node bench/view_bench.mjs VMAP_BINARY MAP.vmap [--scene SCENE] [--clicks 30] [--frames 120]
//        [--size 1280x800] [--json out.json] [--shot picture.png]
// Starts `vmap view MAP`, loads the page and measures
//   clicks: points on screen are clicked (real mouse events) one after another; per click the
//     time from the mouse-up to the recoloured picture drawn and finished (pick, POST
//     /api/visible, JSON parse, colour update, one frame), with the server's own time for
//     visible_set and the visible count (the work);
//   frames: the camera orbits the scene in `frames` steps; each frame is rendered and finished
//     (a one-pixel read waits for the rasteriser), ms per frame, all points drawn; and the
//     frame rate the page reaches with requestAnimationFrame while the view orbits for 4 s, when
//     it draws a shuffled prefix of the points sized to hold 30 fps (web/viewer.js), with the
//     number of points it settled on;
//   answers: the visible set as a JSON list or a base64 bit mask, fetched from node.
// Prints medians with min and max; the first click and 10 frames warm up and are not counted.
import {spawn} from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';
import {fileURLToPath} from 'node:url';

import {launch, missing, startView} from '../tests/browser/chromium.mjs';

const args = process.argv.slice(2);
const opt = (name, def) => {
    const i = args.indexOf(name);
    return i >= 0 ? args[i + 1] : def;
};
const [vmap, map] = args;
if (!vmap || !map) {
    console.error(
        'usage: node bench/view_bench.mjs VMAP_BINARY MAP.vmap [--scene S] [--clicks N] ' +
        '[--frames N] [--size WxH] [--json out.json]');
    process.exit(2);
}
const src = path.resolve(path.dirname(fileURLToPath(import.meta.url)), '..');
const why = missing(src);
if (why) {
    console.error(`view_bench: ${why}`);
    process.exit(1);
}
const clicks = Number(opt('--clicks', 30)), frames = Number(opt('--frames', 120));
const [width, height] = opt('--size', '1280x800').split('x').map(Number);

const stats = (xs) => {
    const s = [...xs].sort((a, b) => a - b);
    return {median: s[Math.floor(s.length / 2)], min: s[0], max: s[s.length - 1], n: s.length};
};
const fmt = (s, unit = 'ms') => `median ${s.median.toFixed(1)} ${unit} (min ${
    s.min.toFixed(1)}, max ${s.max.toFixed(1)}, n ${s.n})`;

// The picture for the README: the Fig. 9 eye on the floor clicked, a ray along the view, and a
// pair query with a point high on the back wall.
async function screenshot(page, file) {
    await page.keyboard.press('Escape');
    await page.keyboard.press('h');
    await page.evaluate(() => {
        window.vmapView.finishFrames = false;
    });
    const [eye, other] = await page.evaluate((targets) => {
        const v = window.vmapView.viewer;
        return targets.map((t) => {
            const ids = [...Array(v.n).keys()];
            const d = ids.map((i) => v.position(i).distanceToSquared({x: t[0], y: t[1], z: t[2]}));
            ids.sort((a, b) => d[a] - d[b]);
            return v.screenOf(ids.find((i) => {
                const s = v.screenOf(i);
                return s && v.pickAt(s.x, s.y) === i;
            }));
        });
    }, [[0.2764, 0, 0.1], [0.12, 0.42, 0.5592]]);
    await page.evaluate(() => {
        delete document.body.dataset.count;
    });
    await page.mouse.click(eye.x, eye.y);
    await page.waitForFunction('document.body.dataset.count !== undefined');
    await page.keyboard.down('Shift');
    await page.mouse.click(other.x, other.y);
    await page.keyboard.up('Shift');
    await page.waitForFunction('document.body.dataset.pair !== undefined');
    await page.keyboard.press('r');
    await page.waitForFunction('document.body.dataset.ray !== undefined');
    await new Promise((r) => setTimeout(r, 500));
    await page.screenshot({path: file});
    console.log(`wrote:      ${file}`);
}

// The visible set as a JSON list or as a base64 bit mask, requested from node (no browser)
// alternately for 20 ids, each answer decoded: ms per request.
async function answerFormats(url, n) {
    const t = {ids: [], bits: []};
    for (let k = 0; k < 40; ++k) {
        const as = k % 2 ? 'bits' : 'ids';
        const t0 = performance.now();
        const r = await fetch(
            `${url}api/visible`,
            {method: 'POST', body: JSON.stringify({id: ((k >> 1) * 7919) % n, as})});
        const j = await r.json();
        if (as === 'bits') Uint8Array.from(atob(j.bits), (c) => c.charCodeAt(0));
        t[as].push(performance.now() - t0);
    }
    result.list_ms = stats(t.ids);
    result.bits_ms = stats(t.bits);
    console.log(`answers:    visible set as a JSON list ${fmt(result.list_ms)}`);
    console.log(`            as a bit mask ${fmt(result.bits_ms)} (from node, alternating)`);
}

const viewArgs = [map, ...(opt('--scene') ? ['--scene', opt('--scene')] : [])];
const server = startView(spawn, vmap, viewArgs);
const tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'vmap-view-bench-'));
const browser = await launch(tmp);
const result = {
    map,
    width,
    height
};
try {
    const url = await server.url;
    const page = await browser.newPage();
    await page.setViewport({width, height, deviceScaleFactor: 1});
    await page.goto(url);
    await page.waitForFunction('window.vmapView.ready || window.vmapView.error', {timeout: 120000});
    const info = await page.evaluate(() => window.vmapView.viewer.info);
    result.points = info.points;
    result.renderer = await page.evaluate(() => {
        const gl = window.vmapView.viewer.renderer.getContext();
        const d = gl.getExtension('WEBGL_debug_renderer_info');
        return d ? gl.getParameter(d.UNMASKED_RENDERER_WEBGL) : gl.getParameter(gl.RENDERER);
    });
    console.log(
        `map:        ${map}: ${info.points} points, ${info.leaves} leaves, height ${info.height}`);
    console.log(
        `browser:    ${await browser.version()}, ${width}x${height}, WebGL on ${result.renderer}`);

    // Click targets: a grid over the canvas right of the panel, kept where a point is hit.
    const targets = await page.evaluate((want) => {
        const v = window.vmapView.viewer, out = [];
        const panel = document.getElementById('panel').getBoundingClientRect();
        for (let k = 0; out.length < want && k < 40 * want; ++k) {
            const x = panel.right + 10 + ((k * 0.618034) % 1) * (innerWidth - panel.right - 20);
            const y = 10 + ((k * 0.7548777) % 1) * (innerHeight - 20);
            if (v.pickAt(x, y) >= 0) out.push([x, y]);
        }
        return out;
    }, clicks + 1);
    await page.evaluate(() => {
        window.vmapView.finishFrames = true;
    });
    const lat = [], server_ms = [], counts = [],
          parts = {pick: [], fetch: [], draw: [], finish: []};
    for (const [k, [x, y]] of targets.entries()) {
        await page.evaluate(() => {
            delete document.body.dataset.count;
        });
        await page.mouse.click(x, y);
        await page.waitForFunction('document.body.dataset.count !== undefined', {timeout: 10000});
        const l = await page.evaluate(() => window.vmapView.viewer.latency);
        const c = await page.evaluate(() => Number(document.body.dataset.count));
        if (k === 0) continue;
        lat.push(l.total), server_ms.push(l.server), counts.push(c);
        for (const k of Object.keys(parts)) parts[k].push(l[k]);
    }
    result.click_ms = stats(lat);
    result.server_ms = stats(server_ms);
    result.visible = stats(counts);
    console.log(`click:      click to recoloured picture ${fmt(result.click_ms)}`);
    for (const k of Object.keys(parts)) result[`${k}_ms`] = stats(parts[k]);
    console.log(`            of which pick ${fmt(result.pick_ms)}`);
    console.log(`            fetch (request, server, JSON parse) ${fmt(result.fetch_ms)}`);
    console.log(`            recolour and submit the frame ${fmt(result.draw_ms)}`);
    console.log(`            wait for the frame to be drawn ${fmt(result.finish_ms)}`);
    console.log(`            server visible_set + JSON ${fmt(result.server_ms)}`);
    console.log(`            visible points per click ${fmt(result.visible, '')}`);

    await page.keyboard.press('Escape');
    const times = await page.evaluate((n) => window.vmapView.viewer.timeFrames(n), frames + 10);
    result.frame_ms = stats(times.slice(10));
    console.log(
        `frames:     rendered and finished ${fmt(result.frame_ms)} = ` +
        `${(1000 / result.frame_ms.median).toFixed(1)} fps`);
    // Moving: the page draws a prefix of its shuffled points, sized to the frame time.
    const moving = await page.evaluate(
        () => new Promise((resolve) => {
            const v = window.vmapView.viewer, t0 = performance.now(), f0 = v.frames, drawn = [];
            const step = () => {
                v.orbitStep(0.01);
                drawn.push(v.drawn);
                if (performance.now() - t0 < 4000)
                    requestAnimationFrame(step);
                else
                    resolve({
                        fps: (v.frames - f0) / ((performance.now() - t0) / 1000),
                        drawn: drawn.slice(drawn.length >> 1)
                    });
            };
            requestAnimationFrame(step);
        }));
    result.moving_fps = moving.fps;
    result.moving_points = stats(moving.drawn);
    console.log(
        `moving:     orbiting for 4 s (requestAnimationFrame): ${moving.fps.toFixed(1)} fps, ` +
        `drawing ${fmt(result.moving_points, 'points')} (last 2 s)`);
    await answerFormats(url, info.points);
    if (opt('--shot')) await screenshot(page, opt('--shot'));
} finally {
    await browser.close();
    server.child.kill('SIGINT');
    await server.exited;
    fs.rmSync(tmp, {recursive: true, force: true});
}
if (opt('--json')) fs.writeFileSync(opt('--json'), JSON.stringify(result, null, 2) + '\n');
