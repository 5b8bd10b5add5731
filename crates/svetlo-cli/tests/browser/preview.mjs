// Headless Chromium against the svetlo preview (run by ../preview_browser.rs, which passes
// SVETLO_BIN, SVETLO_SCENE, SVETLO_OUT and CHROMIUM). Every wait polls with a timeout; no
// fixed sleep decides a result. Prints one line `RESULT {json}` for the Rust side to check.
import { chromium } from 'playwright-core';
import { spawn } from 'node:child_process';
import { existsSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';

const BIN = process.env.SVETLO_BIN, SCENE = process.env.SVETLO_SCENE, OUT = process.env.SVETLO_OUT;
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
const T = 60_000; // per wait: generous for a loaded 2-core machine
const result = {};
const t0 = Date.now();
const phase = (name) => { (result.seconds ||= {})[name] = (Date.now() - t0) / 1000; };

function fail(msg) { throw new Error(msg); }

// Start svetlo; resolve with the preview address it prints, and a promise of its exit.
function start(args) {
  const p = spawn(BIN, args, { stdio: ['ignore', 'pipe', 'pipe'] });
  let out = '', err = '';
  p.stdout.on('data', (d) => { out += d; });
  const exited = new Promise((res) => p.on('exit', (code, sig) => res({ code, sig, out, err })));
  const url = new Promise((res, rej) => {
    p.stderr.on('data', (d) => {
      err += d;
      const m = err.match(/preview: (http:\/\/\S+)/);
      if (m) res(m[1]);
    });
    exited.then((r) => rej(new Error(`svetlo exited before printing its address: ${r.err}`)));
    setTimeout(() => rej(new Error('no preview address within the timeout')), T);
  });
  return { p, url, exited, output: () => ({ out, err }) };
}

// Mean brightness of a canvas's pixels, and how many are not black.
const canvasStats = (sel) => (s) => {
  const c = document.querySelector(s);
  if (!c || !c.width) return null;
  const d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
  let sum = 0, lit = 0;
  for (let i = 0; i < d.length; i += 4) { const v = d[i] + d[i + 1] + d[i + 2]; sum += v; if (v > 30) lit++; }
  return { mean: sum / (d.length / 4) / 3, lit, n: d.length / 4 };
};

const browser = await chromium.launch({ executablePath: CHROMIUM, args: ['--no-sandbox', '--disable-gpu'] });
try {
  phase('launch');
  // ---- 1. svetlo render --preview: the image appears and changes; Stop keeps the samples ----
  const stopExr = join(OUT, 'stopped.exr');
  const r = start(['render', SCENE, '--preview', '--spp', '1000000', '--width', '96', '--height', '96', '--max-depth', '5', '--aov-preset', 'lecture', '-o', stopExr]);
  const page = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  await page.goto(await r.url);
  await page.waitForFunction(() => window.svetlo.framesReceived >= 1 && window.svetlo.drawn >= 1, null, { timeout: T });
  phase('first image');
  const canvas = page.locator('.view canvas').first();
  const shot1 = await canvas.screenshot();
  const spp1 = await page.evaluate(() => window.svetlo.frames[0].spp);
  await page.waitForFunction((s) => window.svetlo.frames[0] && window.svetlo.frames[0].spp > s, spp1, { timeout: T });
  await page.waitForFunction((n) => window.svetlo.drawn > n, await page.evaluate(() => window.svetlo.drawn), { timeout: T });
  const shot2 = await canvas.screenshot();
  if (shot1.equals(shot2)) fail('the image did not change between two passes');
  const stats = await page.evaluate(canvasStats(), '.view canvas');
  if (!stats || stats.lit < stats.n / 4) fail(`the image is mostly black: ${JSON.stringify(stats)}`);
  result.render = { spp1, spp2: await page.evaluate(() => window.svetlo.frames[0].spp), lit: stats.lit / stats.n };
  await page.screenshot({ path: join(OUT, 'render.png') });
  phase('changed');
  // The render's AOVs (--aov-preset lecture) are in the layer menu; choosing one brings its frames.
  const options = await page.$$eval('#layer option', (os) => os.map((o) => o.value));
  if (!options.includes('radiosity')) fail(`no AOV in the layer menu: ${options}`);
  await page.selectOption('#layer', 'radiosity');
  await page.waitForFunction((i) => window.svetlo.frames[0] && window.svetlo.frames[0].layer === i, options.indexOf('radiosity'), { timeout: T });
  phase('aov layer');
  await page.click('#stop');
  const ended = await Promise.race([r.exited, new Promise((res) => setTimeout(() => res(null), T))]);
  if (!ended) { r.p.kill(); fail('the render did not stop after the Stop button'); }
  const m = ended.out.match(/spp\s+(\d+) \(of (\d+)\)/);
  if (ended.code !== 130 || !m) fail(`stopped render: exit ${ended.code}, output ${ended.out} ${ended.err}`);
  if (!existsSync(stopExr)) fail('no EXR after stopping');
  // The page keeps the last image and says the render was stopped.
  await page.waitForFunction(() => window.svetlo.status && window.svetlo.status.slots[0].state === 'stopped', null, { timeout: T });
  phase('stopped');
  result.stop = { exit: ended.code, spp: +m[1], of: +m[2], exr: stopExr };
  await page.close();

  // ---- 2. svetlo serve --compare: split view, plot, table; the integrator changes from the page ----
  const s = start(['serve', SCENE, '--compare', 'path,direct', '--time', '1.5', '--width', '80', '--height', '80', '--max-depth', '5', '-o', join(OUT, 'cmp.exr')]);
  const p2 = await browser.newPage({ viewport: { width: 1280, height: 900 } });
  await p2.goto(await s.url);
  await p2.waitForFunction(() => { const st = window.svetlo.status; return st && st.slots.length === 2 && st.slots.every((x) => x.state === 'done') && window.svetlo.frames[1]; }, null, { timeout: T });
  phase('compare done');
  await p2.check('input[name=layout][value=split]');
  await p2.waitForFunction(() => document.querySelectorAll('.view').length === 1 && document.getElementById('divider') && window.svetlo.drawn > 0, null, { timeout: T });
  await p2.waitForFunction(() => document.querySelectorAll('.view canvas').length === 2 && [...document.querySelectorAll('.view canvas')].every((c) => c.width > 0), null, { timeout: T });
  // Drag the divider to a quarter of the view: the split follows.
  const view = await p2.locator('.view').boundingBox();
  const div = await p2.locator('#divider').boundingBox();
  await p2.mouse.move(div.x + div.width / 2, div.y + div.height / 2);
  await p2.mouse.down();
  await p2.mouse.move(view.x + view.width * 0.25, view.y + view.height / 2, { steps: 5 });
  await p2.mouse.up();
  const split = await p2.evaluate(() => window.svetlo.split);
  if (Math.abs(split - 0.25) > 0.05) fail(`the divider did not move: split ${split}`);
  const a = await p2.evaluate(canvasStats(), '.view canvas[data-slot="0"]');
  const b = await p2.evaluate(canvasStats(), '.view canvas[data-slot="1"]');
  if (!a || !b || a.lit < a.n / 4 || b.lit < b.n / 4) fail(`split view without content: ${JSON.stringify({ a, b })}`);
  // The plot has both curves drawn; the table has both rows with an error.
  const curves = await p2.evaluate(() => window.svetlo.status.slots.map((x) => x.curve.length));
  const plotPixels = await p2.evaluate(() => {
    const c = document.getElementById('plot'), d = c.getContext('2d').getImageData(0, 0, c.width, c.height).data;
    let n = 0; for (let i = 0; i < d.length; i += 4) if (d[i + 3] > 0 && (d[i] > 150 || d[i + 2] > 150)) n++; return n;
  });
  if (curves.some((n) => n < 2) || plotPixels < 100) fail(`plot without content: curves ${curves}, ${plotPixels} pixels`);
  const rows = await p2.locator('#results tbody tr').count();
  if (rows !== 2) fail(`results table has ${rows} rows`);
  await p2.screenshot({ path: join(OUT, 'compare-split.png') });
  result.compare = { split, curves, plotPixels, rows };

  phase('split and plot');
  // Change the integrator from the page: the render restarts with it.
  const run0 = await p2.evaluate(() => window.svetlo.status.run);
  await p2.selectOption('#method-a', 'whitted');
  await p2.selectOption('#method-b', '');
  await p2.fill('#spp', '4');
  await p2.click('#restart');
  await p2.waitForFunction((r0) => { const st = window.svetlo.status; return st.run > r0 && st.config.methods.join() === 'whitted' && st.config.spp === 4 && st.slots.length === 1; }, run0, { timeout: T });
  await p2.waitForFunction(() => { const st = window.svetlo.status, f = window.svetlo.frames[0]; return f && f.run === st.run && st.slots[0].state === 'done'; }, null, { timeout: T });
  await p2.screenshot({ path: join(OUT, 'restarted.png') });
  phase('restarted');
  result.restart = { run0, run: await p2.evaluate(() => window.svetlo.status.run), exr: join(OUT, 'cmp-whitted.exr') };
  s.p.kill('SIGTERM');
  await s.exited;
  if (!existsSync(join(OUT, 'cmp-path.exr')) || !existsSync(join(OUT, 'cmp-direct.exr'))) fail('compare images not written');
} finally {
  await browser.close();
}
writeFileSync(join(OUT, 'result.json'), JSON.stringify(result));
console.log(`RESULT ${JSON.stringify(result)}`);
