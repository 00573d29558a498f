// The terminal page when the daemon falls silent without closing anything,
// in headless Chromium at phone size (tests/serve_browser.rs):
//
//   node tests/browser/serve-silent.mjs URL TOKEN SCREENSHOT_DIR CUT NAME [zh]
//
// CUT is how the daemon falls silent: `sigstop:PID` stops the daemon's
// process (SIGSTOP: its sockets stay open and the kernel still accepts
// connections), `proxy:HOST:PORT` tells the test's proxy between the page
// and the daemon to stop forwarding (a Wi-Fi link that drops without
// closing). Presses Calibrate and confirms, waits for pose 3, cuts, and
// measures how long the page takes to say that contact is lost; then presses
// Abort, which must say that it could not be sent and is pending (never
// "aborting…"), with Abort and that note on the 390×844 screen; then resumes
// (SIGCONT, or the proxy forwards again), noting the wall-clock time, and
// waits for the page to find the daemon again and to end on "aborted" (the
// pending Abort sent, or the daemon's own abort after its stall). Saves
// serve-NAME-lost.png, serve-NAME-abort-not-sent.png and
// serve-NAME-aborted.png (with `zh`, the page in Chinese). Prints one JSON
// line of what it saw; exits 0 when every check passes.

import { connect } from 'node:net';
import { resolve } from 'node:path';

import { deadline, launch } from './chromium.mjs';

const [url, token, shotDir, cut, name, lang] = process.argv.slice(2);
const zh = lang === 'zh';
if (!url || !token || !shotDir || !cut || !name) {
  console.error('usage: node serve-silent.mjs URL TOKEN SCREENSHOT_DIR sigstop:PID|proxy:HOST:PORT NAME [zh]');
  process.exit(2);
}
deadline('serve-silent.mjs', 150);

// Tells the test's proxy to freeze or thaw.
function proxy(command) {
  const [host, port] = cut.slice('proxy:'.length).split(':');
  return new Promise((done, fail) => {
    const socket = connect(Number(port), host, () => socket.end(command + '\n'));
    socket.on('close', done);
    socket.on('error', fail);
  });
}
async function silence() {
  if (cut.startsWith('sigstop:')) process.kill(Number(cut.slice(8)), 'SIGSTOP');
  else await proxy('freeze');
}
async function resume() {
  if (cut.startsWith('sigstop:')) process.kill(Number(cut.slice(8)), 'SIGCONT');
  else await proxy('thaw');
}

const problems = [];
const seen = {};
const shot = (page, suffix) => page.screenshot({ path: resolve(shotDir, `serve-${name}-${suffix}.png`), fullPage: true });
let browser;
let silent = false;
try {
  browser = await launch({ viewport: { width: 390, height: 844 }, isMobile: true, hasTouch: true, deviceScaleFactor: 2 });
  const page = browser.context.pages()[0] ?? (await browser.context.newPage());
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  if (zh) await page.addInitScript(() => localStorage.setItem('groundcal-language', 'zh'));
  await page.goto(url, { waitUntil: 'load', timeout: 30_000 });
  if (!await page.$eval('#token-card', (d) => d.open)) await page.click('#token-card summary');
  await page.fill('#token', token);
  // Before the run: the drift banner (when the daemon found one), the
  // check's lines and the hardware line as drawn, and how legible the
  // banner and the disabled Abort are (WCAG's contrast ratio).
  await page.waitForFunction(() => document.getElementById('hardware').textContent !== '', null, { timeout: 10_000 });
  seen.driftBefore = await page.locator('#drift-text').innerText();
  seen.checksBefore = await page.locator('#checks').innerText();
  seen.checklineBefore = await page.locator('#checkline').innerText();
  seen.hardwareBefore = await page.locator('#hardware').innerText();
  seen.contrast = await page.evaluate(() => {
    const rgb = (c) => c.match(/[\d.]+/g).slice(0, 3).map(Number);
    const lum = ([r, g, b]) => {
      const f = (v) => { v /= 255; return v <= 0.03928 ? v / 12.92 : Math.pow((v + 0.055) / 1.055, 2.4); };
      return 0.2126 * f(r) + 0.7152 * f(g) + 0.0722 * f(b);
    };
    const ratio = (e) => {
      const style = getComputedStyle(e);
      const a = lum(rgb(style.color)); const b = lum(rgb(style.backgroundColor));
      return (Math.max(a, b) + 0.05) / (Math.min(a, b) + 0.05);
    };
    const abort = document.getElementById('abort');
    const live = document.getElementById('calibrate');
    return {
      drift: ratio(document.getElementById('drift')),
      disabledAbort: abort.disabled ? ratio(abort) : null,
      disabledLooksLive: getComputedStyle(abort).borderStyle === getComputedStyle(live).borderStyle,
    };
  });
  await page.click('#calibrate');
  await page.waitForSelector('#confirm-run:not([hidden])');
  await page.click('#confirm-run-yes');
  const poseThree = zh ? /第 ([3-9]|\d\d+) \/ \d+ 个姿态/ : /pose ([3-9]|\d\d+) of \d+/;
  await page.waitForFunction((re) => new RegExp(re).test(document.getElementById('progress').textContent), poseThree.source, { timeout: 60_000 });

  const cutAt = Date.now();
  await silence();
  silent = true;
  await page.waitForFunction(() => !document.getElementById('lost').hidden, null, { timeout: 10_000, polling: 50 });
  seen.lostAfterMs = Date.now() - cutAt;
  seen.banner = await page.locator('#lost').innerText();
  seen.contact = await page.locator('#contact').innerText();
  await shot(page, 'lost');

  seen.abortEnabled = !(await page.$eval('#abort', (b) => b.disabled));
  const pressed = Date.now();
  await page.click('#abort');
  seen.progressAfterAbort = await page.locator('#progress').innerText();
  await page.waitForFunction(() => document.getElementById('abort-note').className === 'pending', null, { timeout: 10_000, polling: 50 });
  seen.abortSaidAfterMs = Date.now() - pressed;
  seen.abortMessage = await page.locator('#abort-note').innerText();
  seen.progressAfterRefusal = await page.locator('#progress').innerText();
  seen.pendingKept = await page.evaluate(() => localStorage.getItem('groundcal-pending-abort'));
  // Abort and what became of it stay on the phone's screen, whatever the
  // banners above push down.
  seen.onScreen = await page.evaluate(() => ['abort', 'abort-note'].map((id) => {
    const r = document.getElementById(id).getBoundingClientRect();
    return { id, top: Math.round(r.top), bottom: Math.round(r.bottom), visible: r.top >= 0 && r.bottom <= window.innerHeight && r.height > 0 };
  }));
  await shot(page, 'abort-not-sent');
  await page.screenshot({ path: resolve(shotDir, `serve-${name}-abort-not-sent-screen.png`) });

  seen.resumedAtUnixMs = Date.now();
  await resume();
  silent = false;
  await page.waitForFunction(() => document.getElementById('lost').hidden
    && document.getElementById('contact').textContent !== '', null, { timeout: 30_000 });
  seen.foundAfterMs = Date.now() - seen.resumedAtUnixMs;
  const aborted = zh ? '已中止' : 'aborted';
  await page.waitForFunction((word) => document.getElementById('progress').textContent.startsWith(word)
    && !localStorage.getItem('groundcal-pending-abort'), aborted, { timeout: 60_000 });
  seen.endedAfterMs = Date.now() - seen.resumedAtUnixMs;
  seen.ended = await page.locator('#progress').innerText();
  seen.endedStep = (await page.locator('#step').innerText()) + ' ' + (await page.locator('#step-detail').innerText());
  seen.endedNote = await page.locator('#abort-note').innerText();
  await page.waitForTimeout(300);
  await shot(page, 'aborted');
} catch (error) {
  problems.push(`the browser failed: ${error.stack ?? error}`);
} finally {
  if (silent) await resume().catch(() => {});
  if (browser) await browser.close();
}
if (seen.lostAfterMs > 3000) problems.push(`contact was declared lost only after ${seen.lostAfterMs} ms`);
if (/aborting/.test(seen.progressAfterAbort || '') || /aborting/.test(seen.progressAfterRefusal || '')) {
  problems.push(`the page pretended to abort: ${seen.progressAfterAbort} / ${seen.progressAfterRefusal}`);
}
console.log(JSON.stringify({ url, seen, problems }));
for (const problem of problems) console.error(`serve-silent.mjs: ${problem}`);
process.exit(problems.length === 0 ? 0 : 1);
