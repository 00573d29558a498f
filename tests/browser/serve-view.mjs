// The page's picture of what the camera sees, and the page in Chinese
// (tests/serve_browser.rs), on a daemon whose simulated world has boxes and
// a wall in view.
//
//   node tests/browser/serve-view.mjs URL TOKEN SCREENSHOT_DIR
//
// 1. A phone (390×844) and a pad (1024×768) in English: the picture is
//    drawn as GET /api/view says, cell by cell: green where the fit took the
//    reading for the ground, grey elsewhere, black without a reading; the
//    floor is coloured and a box in view is not.
// 2. A phone with the browser in Simplified Chinese: the page speaks
//    Chinese (the catalogue has every English word in Chinese too), through
//    the confirmation of Calibrate and a whole calibration to its verdict;
//    the language switch brings English back.
// Saves serve-view-*.png and serve-zh-*.png. Prints one JSON line of what
// it saw; exits 0 when every check passes.

import { resolve } from 'node:path';

import { deadline, launch } from './chromium.mjs';

const [url, token, shotDir] = process.argv.slice(2);
if (!url || !token || !shotDir) {
  console.error('usage: node serve-view.mjs URL TOKEN SCREENSHOT_DIR');
  process.exit(2);
}
deadline('serve-view.mjs', 240);

const problems = [];
const seen = {};
const browsers = [];
async function open(viewport, locale) {
  const browser = await launch({ viewport, isMobile: viewport.width < 800, hasTouch: true, deviceScaleFactor: 2, locale });
  browsers.push(browser);
  const page = browser.context.pages()[0] ?? (await browser.context.newPage());
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('console', (m) => { if (m.type() === 'error') problems.push(`console error: ${m.text()}`); });
  await page.goto(url, { waitUntil: 'load', timeout: 30_000 });
  return page;
}

// The picture as drawn, against the picture the daemon serves: for each
// cell, what its canvas pixel shows and what the API says it is.
async function compareView(page) {
  await page.waitForFunction(() => /\d/.test(document.getElementById('view-when').textContent), null, { timeout: 30_000 });
  return page.evaluate(async () => {
    // The picture served and the one drawn must be the same (one comes a
    // second): fetch until the drawn one is the one served.
    let served = null;
    for (let attempt = 0; attempt < 10; attempt++) {
      served = await (await fetch('/api/view')).json();
      if (drawn.get('view') === served.seq) break;
      await loadView();
    }
    const canvas = document.getElementById('view');
    const pixels = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data;
    const v = served.view;
    const tally = { green: 0, grey: 0, black: 0, wrong: 0, width: canvas.width, height: canvas.height, same: drawn.get('view') === served.seq };
    for (let i = 0; i < v.width * v.height; i++) {
      const [r, g, b] = [pixels[4 * i], pixels[4 * i + 1], pixels[4 * i + 2]];
      const kind = r + g + b === 0 ? 'black' : g > r + 40 && g > b + 40 ? 'green' : Math.abs(r - g) < 3 && Math.abs(g - b) < 3 ? 'grey' : 'other';
      const expected = !v.depth_cm[i] ? 'black' : v.ground[i] ? 'green' : 'grey';
      tally[kind] = (tally[kind] || 0) + 1;
      if (kind !== expected) tally.wrong += 1;
    }
    tally.note = document.getElementById('view-note').textContent;
    tally.when = document.getElementById('view-when').textContent;
    return tally;
  });
}

try {
  // 1. English, phone and pad.
  const phone = await open({ width: 390, height: 844 }, 'en-US');
  const pad = await open({ width: 1024, height: 768 }, 'en-US');
  for (const [name, page] of [['phone', phone], ['pad', pad]]) {
    seen[name] = await compareView(page);
    await page.screenshot({ path: resolve(shotDir, `serve-view-${name}.png`), fullPage: true });
  }
  for (const b of browsers.splice(0)) await b.close();

  // 2. Chinese, on a phone.
  const zh = await open({ width: 390, height: 844 }, 'zh-CN');
  await zh.waitForFunction(() => document.getElementById('progress').textContent === '空闲', null, { timeout: 30_000 });
  seen.zh = await zh.evaluate(() => {
    // Every word of the catalogue in both languages, nested ones included.
    const missing = [];
    const walk = (en, other, path) => {
      for (const [key, value] of Object.entries(en)) {
        if (!(key in other)) missing.push(path + key);
        else if (value && typeof value === 'object' && !Array.isArray(value)) walk(value, other[key], path + key + '.');
      }
    };
    walk(WORDS.en, WORDS.zh, '');
    return {
      lang: document.documentElement.lang,
      calibrate: document.getElementById('calibrate').textContent,
      viewTitle: document.getElementById('view-title').textContent,
      missing,
    };
  });
  // English words the page itself shows (not those marked as the robot's).
  const englishWords = () => zh.evaluate(() => {
    const words = [];
    const walker = document.createTreeWalker(document.querySelector('main'), NodeFilter.SHOW_TEXT);
    for (let n = walker.nextNode(); n; n = walker.nextNode()) {
      const element = n.parentElement;
      if (element.closest('[lang="en"]') || element.closest('[hidden]') || element.closest('svg') || element.closest('option')) continue;
      // File paths (/etc/groundcal/token) are names, not words.
      for (const w of n.textContent.replace(/\S*\/\S*/g, '').match(/[A-Za-z]{4,}/g) || []) {
        if (!['groundcal', 'Kinect', 'preview_interval_ms', 'serve'].includes(w)) words.push(w);
      }
    }
    return words;
  });
  seen.zhEnglishIdle = await englishWords();
  await zh.screenshot({ path: resolve(shotDir, 'serve-zh-1-idle.png'), fullPage: true });
  if (!await zh.$eval('#token-card', (d) => d.open)) await zh.click('#token-card summary');
  await zh.fill('#token', token);
  await zh.click('#calibrate');
  await zh.waitForSelector('#confirm-run:not([hidden])');
  seen.zhConfirm = await zh.locator('#confirm-run-text').innerText();
  await zh.screenshot({ path: resolve(shotDir, 'serve-zh-2-confirm.png'), fullPage: true });
  await zh.click('#confirm-run-yes');
  await zh.waitForFunction(() => /^第 \d+ \/ \d+ 个姿态$/.test(document.getElementById('progress').textContent), null, { timeout: 60_000 });
  seen.zhRunning = await zh.locator('#progress').innerText();
  seen.zhStep = await zh.locator('#step').innerText();
  seen.zhEnglishRunning = await englishWords();
  await zh.screenshot({ path: resolve(shotDir, 'serve-zh-3-running.png'), fullPage: true });
  await zh.waitForFunction(() => !document.getElementById('result').hidden && /检查/.test(document.getElementById('verdict').textContent), null, { timeout: 180_000 });
  seen.zhVerdict = await zh.locator('#verdict').innerText();
  seen.zhGates = await zh.locator('#gates-title').innerText();
  seen.zhEnglishResult = await englishWords();
  // The Kinect's own warp, drawn from the stored calibration's cells: each
  // cell as its value says (red farther, blue nearer, grey unseen).
  await zh.waitForFunction(() => !document.getElementById('warp').hidden, null, { timeout: 15_000 });
  const warp = () => zh.evaluate(async () => {
    const canvas = document.getElementById('warp');
    const id = document.getElementById('resultid').dataset.id;
    const stored = await (await fetch('/api/calibrations/' + encodeURIComponent(id))).json();
    const p = stored.depth_pattern;
    const data = canvas.getContext('2d').getImageData(0, 0, canvas.width, canvas.height).data;
    let wrong = 0, farther = 0, nearer = 0, unseen = 0;
    p.raw.forEach((raw, i) => {
      const [r, g, b] = [data[4 * i], data[4 * i + 1], data[4 * i + 2]];
      if (raw === null) {
        unseen++;
        if (!(r === 190 && g === 190 && b === 190)) wrong++;
        return;
      }
      const error = -4 * raw / p.raw_per_inverse_depth * 1000;
      if (error > 0.5) { farther++; if (!(r > b)) wrong++; }
      if (error < -0.5) { nearer++; if (!(b > r)) wrong++; }
    });
    const box = canvas.getBoundingClientRect();
    return {
      corrected: p.corrected, columns: canvas.width, rows: canvas.height, cells: p.raw.length,
      width: box.width, wrong, farther, nearer, unseen,
      words: document.getElementById('warp-words').textContent,
      ticks: [...document.querySelectorAll('#warp-ticks span')].map((s) => s.textContent),
    };
  });
  seen.zhWarp = await warp();
  await zh.screenshot({ path: resolve(shotDir, 'serve-zh-4-result.png'), fullPage: true });
  await zh.selectOption('#language', 'en');
  seen.switchedBack = await zh.locator('#verdict').innerText();
  await zh.waitForFunction(() => /Kinect/.test(document.getElementById('warp-words').textContent), null, { timeout: 5_000 });
  seen.warp = await warp();
  await zh.locator('#warp-box').scrollIntoViewIfNeeded();
  await zh.screenshot({ path: resolve(shotDir, 'serve-warp.png') });
  seen.switchedLang = await zh.evaluate(() => document.documentElement.lang);
} catch (error) {
  problems.push(`the browser failed: ${error.stack ?? error}`);
} finally {
  for (const b of browsers) await b.close();
}

for (const name of ['phone', 'pad']) {
  const v = seen[name];
  if (!v) continue;
  if (!v.same) problems.push(`${name}: the picture drawn never matched the one served`);
  if (v.wrong !== 0) problems.push(`${name}: ${v.wrong} cells drawn otherwise than the daemon says`);
  if (!(v.green >= 500)) problems.push(`${name}: only ${v.green} cells of ground coloured`);
  if (!(v.grey >= 300)) problems.push(`${name}: only ${v.grey} cells left uncoloured: the boxes and the wall are in view`);
}
if (seen.zh) {
  if (seen.zh.missing.length) problems.push(`words missing in Chinese: ${seen.zh.missing.join(', ')}`);
  if (seen.zh.lang !== 'zh-CN' || seen.zh.calibrate !== '标定') problems.push(`the page did not follow the browser's Chinese: ${JSON.stringify(seen.zh)}`);
}
for (const key of ['zhEnglishIdle', 'zhEnglishRunning', 'zhEnglishResult']) {
  if (seen[key] && seen[key].length) problems.push(`${key}: English on the Chinese page: ${seen[key].join(' ')}`);
}
if (seen.switchedBack && !/checks/.test(seen.switchedBack)) problems.push(`the switch to English left "${seen.switchedBack}"`);
for (const key of ['zhWarp', 'warp']) {
  const w = seen[key];
  if (!w) continue;
  if (w.wrong !== 0) problems.push(`${key}: ${w.wrong} cells of the warp drawn otherwise than the calibration says`);
  if (w.columns * w.rows !== w.cells) problems.push(`${key}: a canvas of ${w.columns} × ${w.rows} for ${w.cells} cells`);
  if (!(w.width >= 300)) problems.push(`${key}: the warp is ${w.width} px wide on a phone`);
}
console.log(JSON.stringify({ url, seen, problems }));
for (const problem of problems) console.error(`serve-view.mjs: ${problem}`);
process.exit(problems.length === 0 ? 0 : 1);
