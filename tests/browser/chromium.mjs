// Debian's chromium, headless, for the viewer's browser test and benchmark: puppeteer-core from
// tests/browser/node_modules (scripts/fetch-web.sh), a fresh profile in `profileDir`, no network
// of its own, software WebGL (SwiftShader: the GPU is off).
import fs from 'node:fs';
import path from 'node:path';
import {fileURLToPath} from 'node:url';

const here = path.dirname(fileURLToPath(import.meta.url));
export const chromiumPath = process.env.VMAP_CHROMIUM || '/usr/bin/chromium';
export const puppeteerPath =
    path.join(here, 'node_modules/puppeteer-core/lib/esm/puppeteer/puppeteer-core.js');

// Why the browser cannot run here, or null.
export function missing(sourceDir) {
    if (!fs.existsSync(chromiumPath))
        return `${chromiumPath} not found (scripts/setup.sh installs chromium)`;
    if (!fs.existsSync(puppeteerPath)) return 'puppeteer-core not installed (scripts/fetch-web.sh)';
    if (!fs.existsSync(path.join(sourceDir, 'web/vendor/three.module.js')))
        return 'three.js not vendored (scripts/fetch-web.sh)';
    return null;
}

export async function launch(profileDir) {
    const {default: puppeteer} = await import(puppeteerPath);
    return puppeteer.launch({
        executablePath: chromiumPath,
        headless: true,
        args: [
            '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
            '--disable-background-networking', '--disable-component-update', '--disable-sync',
            '--enable-unsafe-swiftshader', `--user-data-dir=${profileDir}`
        ],
    });
}

// Starts `vmap view ARGS...`; url resolves to the printed URL, exited to {code, sig}.
export function startView(spawn, vmap, args) {
    const child = spawn(vmap, ['view', ...args], {stdio: ['ignore', 'pipe', 'pipe']});
    let out = '';
    child.stdout.on('data', (d) => {
        out += d;
    });
    child.stderr.on('data', (d) => {
        out += d;
    });
    const exited = new Promise((resolve) => child.on('exit', (code, sig) => resolve({code, sig})));
    const url = new Promise((resolve, reject) => {
        const t = setInterval(() => {
            const m = out.match(/url: +(http:\/\/\S+)/);
            if (m) {
                clearInterval(t);
                resolve(m[1]);
            }
        }, 50);
        exited.then((e) => {
            clearInterval(t);
            reject(new Error(`vmap view exited ${e.code}: ${out}`));
        });
    });
    return {child, url, exited, output: () => out};
}
