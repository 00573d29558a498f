// The terminal page when the daemon falls silent without closing anything,
// in headless Chromium at phone size (tests/serve_browser.rs):
//
//   node tests/browser/serve-silent.mjs URL TOKEN SCREENSHOT_DIR CUT NAME
//
// CUT is how the daemon falls silent: `sigstop:PID` stops the daemon's
// process (SIGSTOP: its sockets stay open and the kernel still accepts
// connections), `proxy:HOST:PORT` tells the test's proxy between the page
// and the daemon to stop forwarding (a Wi-Fi link that drops without
// closing). Presses Calibrate and confirms, waits for pose 3, cuts, and
// measures how long the page takes to say that contact is lost; then presses
// Abort, which must say that it could not be sent (never "aborting…"); then
// resumes (SIGCONT, or the proxy forwards again) and waits for the page to
// find the daemon again. Saves serve-NAME-lost.png and
// serve-NAME-abort-not-sent.png. Prints one JSON line of what it saw; exits
// 0 when every check passes.

import { connect } from 'node:net';
import { resolve } from 'node:path';

import { deadline, launch } from './chromium.mjs';

const [url, token, shotDir, cut, name] = process.argv.slice(2);
if (!url || !token || !shotDir || !cut || !name) {
  console.error('usage: node serve-silent.mjs URL TOKEN SCREENSHOT_DIR sigstop:PID|proxy:HOST:PORT NAME');
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
  await page.goto(url, { waitUntil: 'load', timeout: 30_000 });
  if (!await page.$eval('#token-card', (d) => d.open)) await page.click('#token-card summary');
  await page.fill('#token', token);
  await page.click('#calibrate');
  await page.waitForSelector('#confirm-run:not([hidden])');
  await page.click('#confirm-run-yes');
  await page.waitForFunction(() => /pose ([3-9]|\d\d+) of \d+/.test(document.getElementById('progress').textContent), null, { timeout: 60_000 });

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
  await page.waitForFunction(() => /could not be sent/.test(document.getElementById('message').textContent), null, { timeout: 10_000, polling: 50 });
  seen.abortSaidAfterMs = Date.now() - pressed;
  seen.abortMessage = await page.locator('#message').innerText();
  seen.progressAfterRefusal = await page.locator('#progress').innerText();
  await shot(page, 'abort-not-sent');

  const resumed = Date.now();
  await resume();
  silent = false;
  await page.waitForFunction(() => document.getElementById('lost').hidden
    && document.getElementById('contact').textContent === 'connected', null, { timeout: 30_000 });
  seen.foundAfterMs = Date.now() - resumed;
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
