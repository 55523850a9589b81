// `vmap view` in a real browser: Debian's chromium, headless, driven by puppeteer-core.
//   node view_browser_test.mjs VMAP_BINARY SOURCE_DIR
// Builds a small V-map, starts `vmap view`, loads the page, clicks a known point and checks the
// page against the CLI (`vmap query` on the same file): the eye, the visible count, the colours
// of the points in a screenshot, a pair query and a ray; then stops the server with SIGINT.
// Exit 0: all passed; 1: a check failed; 77: skipped (prerequisite missing).
import {execFileSync, spawn} from 'node:child_process';
import fs from 'node:fs';
import os from 'node:os';
import path from 'node:path';

import {launch, missing, startView} from './chromium.mjs';

const [vmap, src] = process.argv.slice(2);
const shotPath = process.env.VMAP_VIEW_SCREENSHOT;  // also save the final screenshot there
const why = missing(src);
if (why) {
    console.log(`SKIPPED: ${why}`);
    process.exit(77);
}

let passed = 0, failed = 0;
function check(ok, what) {
    console.log(`${ok ? 'ok' : 'FAILED'} - ${what}`);
    ok ? ++passed : ++failed;
}

const tmp = fs.mkdtempSync(path.join(os.tmpdir(), 'vmap-view-browser-'));
const cli = (...args) => execFileSync(vmap, args, {encoding: 'utf8'});
const map = path.join(tmp, 'small.vmap');
const scene = path.join(src, 'scenes/cornell-bunny.json');
cli('build', scene, '--points', '3000', '-o', map);

// Pixels of a screenshot at the given points, decoded by the browser itself.
async function pixelsAt(page, points) {
    const png = await page.screenshot({encoding: 'base64'});
    return page.evaluate(async (b64, pts) => {
        const img = new Image();
        img.src = `data:image/png;base64,${b64}`;
        await img.decode();
        const c = document.createElement('canvas');
        c.width = img.width, c.height = img.height;
        const g = c.getContext('2d');
        g.drawImage(img, 0, 0);
        const d = g.getImageData(0, 0, c.width, c.height).data;
        return pts.map(
            ([x, y]) => Array.from(d.slice(4 * (y * c.width + x), 4 * (y * c.width + x) + 3)));
    }, png, points);
}

const near = (p, q, tol = 16) => p.every((v, i) => Math.abs(v - q[i]) <= tol);
const kPurple = [149, 39, 220], kCyan = [0, 238, 238];

const server = startView(spawn, vmap, [map, '--scene', scene]);
const userDir = fs.mkdtempSync(path.join(tmp, 'chromium-'));
const browser = await launch(userDir);
try {
    const url = await server.url;
    const page = await browser.newPage();
    page.on('pageerror', (e) => check(false, `no page error (${e.message})`));
    await page.setViewport({width: 900, height: 800, deviceScaleFactor: 1});
    await page.goto(url);
    await page.waitForFunction('window.vmapView.ready || window.vmapView.error', {timeout: 30000});
    check(!(await page.evaluate('window.vmapView.error')), 'the page loads the map');
    await page.select('#mode', 'albedo');  // flat colours: purple is purple
    await page.evaluate(() => {
        const s = document.getElementById('splat');
        s.value = '0.7';
        s.dispatchEvent(new Event('input'));
    });

    // The known points: nearest to the Fig. 9 eye on the floor in front of the bunny, and to a
    // spot high on the back wall, among the points that are not covered on screen.
    const [eye, second] = await page.evaluate((targets) => {
        const v = window.vmapView.viewer;
        return targets.map((t) => {
            const ids = [...Array(v.n).keys()];
            const d = ids.map((i) => v.position(i).distanceToSquared({x: t[0], y: t[1], z: t[2]}));
            ids.sort((a, b) => d[a] - d[b]);
            return ids.find((i) => {
                const s = v.screenOf(i);
                return s && v.pickAt(s.x, s.y) === i;
            });
        });
    }, [[0.2764, 0, 0.1], [0.08, 0.45, 0.5592]]);
    // With --ids, stdout holds the ids alone (one a line); the sentence goes to stderr.
    const fromOut = cli('query', map, '--from', String(eye), '--ids');
    const visibleIds = fromOut.split('\n').filter((l) => /^\d+$/.test(l)).map(Number);
    const count = visibleIds.length;
    const pairResult =
        cli('query', map, '--pair', String(eye), String(second)).trim().split(' ')[2];

    // Screen positions of the eye, a sample of visible and of hidden points (not under the panel).
    const sample = await page.evaluate((eyeId, visList) => {
        const v = window.vmapView.viewer;
        const panel = document.getElementById('panel').getBoundingClientRect();
        const visSet = new Set(visList), out = {vis: [], hid: []};
        for (let id = 0; id < v.n; id += 1) {
            const s = v.screenOf(id);
            if (!s || s.x < 2 || s.y < 2 || s.x > innerWidth - 3 || s.y > innerHeight - 3) continue;
            if (s.x < panel.right + 4 && s.y < panel.bottom + 4) continue;
            if (v.pickAt(s.x, s.y) !== id) continue;  // covered by a nearer point
            (visSet.has(id) ? out.vis : out.hid).push([
                id, Math.round(s.x - 0.5), Math.round(s.y - 0.5)
            ]);
        }
        return {eye: v.screenOf(eyeId), ...out};
    }, eye, visibleIds);

    const before = await pixelsAt(page, sample.vis.map((s) => [s[1], s[2]]));
    check(before.filter((p) => near(p, kPurple)).length === 0, 'no purple before the click');

    await page.mouse.click(sample.eye.x, sample.eye.y);
    await page.waitForFunction('document.body.dataset.count !== undefined', {timeout: 10000});
    const shown = await page.evaluate(() => ({
                                          eye: Number(document.body.dataset.eye),
                                          count: Number(document.body.dataset.count),
                                          text: document.getElementById('count').textContent,
                                          latency: window.vmapView.viewer.latency,
                                      }));
    check(shown.eye === eye, `the click picks the known point ${eye} (page: ${shown.eye})`);
    check(shown.count === count, `visible count ${shown.count} equals the CLI's ${count}`);
    check(shown.text.startsWith(`${count} of 3000`), `the panel says "${shown.text}"`);
    console.log(`click to picture: ${JSON.stringify(shown.latency)}`);

    // The colours in a screenshot against the CLI's visible set (eye leaf points are cyan).
    const leaf = new Set(await page.evaluate('window.vmapView.viewer.visible.leaf_ids'));
    const vs = sample.vis.filter((s) => !leaf.has(s[0])),
          hs = sample.hid.filter((s) => !leaf.has(s[0]));
    const pv = await pixelsAt(page, vs.map((s) => [s[1], s[2]]));
    const ph = await pixelsAt(page, hs.map((s) => [s[1], s[2]]));
    const fv = pv.filter((p) => near(p, kPurple)).length / Math.max(1, pv.length);
    const fh = ph.filter((p) => near(p, kPurple)).length / Math.max(1, ph.length);
    check(
        vs.length > 50 && fv > 0.9,
        `${(100 * fv).toFixed(1)}% of ${vs.length} visible points on screen are purple`);
    check(
        hs.length > 50 && fh < 0.05,
        `${(100 * fh).toFixed(1)}% of ${hs.length} hidden points on screen are purple`);
    const [eyePx] = await pixelsAt(page, [[Math.round(sample.eye.x), Math.round(sample.eye.y)]]);
    check(near(eyePx, kCyan, 40), `the eye is drawn cyan (${eyePx})`);

    // Pair query by shift-click on the second point.
    const b = await page.evaluate((id) => window.vmapView.viewer.screenOf(id), second);
    await page.keyboard.down('Shift');
    await page.mouse.click(b.x, b.y);
    await page.keyboard.up('Shift');
    await page.waitForFunction('document.body.dataset.pair !== undefined', {timeout: 10000});
    const pair = await page.evaluate(() => document.body.dataset.pair);
    check(pair === pairResult, `pair ${eye} ${second}: page "${pair}", CLI "${pairResult}"`);

    // A ray from the eye along the view direction, against the CLI with the same direction.
    await page.keyboard.press('r');
    await page.waitForFunction('document.body.dataset.ray !== undefined', {timeout: 10000});
    const ray = await page.evaluate(() => {
        const v = window.vmapView.viewer;
        return {hit: document.body.dataset.ray, dir: v.ray.dir.toArray()};
    });
    const rayOut = cli('query', map, '--ray', String(eye), '--dir', ray.dir.join(','));
    const cliHit = (rayOut.match(/hits point (\d+)/) || [, 'none'])[1];
    check(ray.hit === cliHit, `ray from ${eye}: page hits ${ray.hit}, CLI ${cliHit}`);
    if (shotPath) await page.screenshot({path: shotPath});

    // Walk mode: F, then W held moves the camera forward along the view direction.
    const cam = () => page.evaluate(() => {
        const v = window.vmapView.viewer, d = v.camera.getWorldDirection(v.camera.position.clone());
        return {p: v.camera.position.toArray(), d: d.toArray()};
    });
    const c0 = await cam();
    await page.keyboard.press('f');
    const f0 = await page.evaluate('window.vmapView.viewer.frames');
    await page.keyboard.down('w');
    // Held for at least three frames, however slow the machine.
    await page.waitForFunction(`window.vmapView.viewer.frames >= ${f0 + 3}`, {timeout: 20000});
    await page.keyboard.up('w');
    const c1 = await cam();
    const step = c1.p.map((v, i) => v - c0.p[i]);
    const along = step.reduce((a, v, i) => a + v * c0.d[i], 0);
    check(
        along > 0.005 && Math.hypot(...step) < along * 1.01,
        `W walks forward (${along.toFixed(3)})`);
} catch (e) {
    check(false, `no exception (${e.stack})`);
} finally {
    await browser.close();
}

server.child.kill('SIGINT');
const ended =
    await Promise.race([server.exited, new Promise((r) => setTimeout(() => r(null), 10000))]);
check(ended && ended.code === 0, `SIGINT stops the server with exit 0 (${JSON.stringify(ended)})`);
check(/stopped\./.test(server.output()), 'the server says it stopped');
if (!ended) server.child.kill('SIGKILL');
fs.rmSync(tmp, {recursive: true, force: true});
console.log(`${passed} passed, ${failed} failed`);
process.exit(failed ? 1 : 0);
