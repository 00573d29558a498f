// The terminal page after the daemon was killed mid-run and started again
// with `[verify] at_start` (tests/serve_browser.rs):
//
//   node tests/browser/serve-crash.mjs URL TOKEN SCREENSHOT_DIR RECEIPTS MARK
//
// RECEIPTS is the lower computer's log of the datagrams it handled (one JSON
// line each); MARK is how many lines it had when the daemon restarted. The
// page must show "Interrupted" (who started the run, when, and that nothing
// moves until someone asks), and for 3 s more the lower computer must get
// no HELLO, SET_POSE or HOME. Then Check asks to keep clear; once confirmed,
// the lower computer hears from groundcal. Saves serve-16-interrupted.png and
// serve-16b-confirm-check.png. Prints one JSON line of what it saw; exits 0
// when every check passes.

import { readFileSync } from 'node:fs';
import { resolve } from 'node:path';

import { deadline, launch } from './chromium.mjs';

const [url, token, shotDir, receipts, mark] = process.argv.slice(2);
if (!url || !token || !shotDir || !receipts || mark === undefined) {
  console.error('usage: node serve-crash.mjs URL TOKEN SCREENSHOT_DIR RECEIPTS MARK');
  process.exit(2);
}
deadline('serve-crash.mjs', 120);

// The kinds of the datagrams that reached the lower computer since MARK.
function receivedSinceRestart() {
  return readFileSync(receipts, 'utf8').split('\n').slice(Number(mark))
    .filter((l) => l.trim()).map((l) => JSON.parse(l))
    .filter((r) => r.event === 'datagram').map((r) => r.kind);
}
const CONTACT = ['HELLO', 'SET_POSE', 'HOME'];

const problems = [];
const seen = {};
const shot = (page, name) => page.screenshot({ path: resolve(shotDir, `serve-${name}.png`), fullPage: true });
let browser;
try {
  browser = await launch({ viewport: { width: 390, height: 844 }, isMobile: true, hasTouch: true, deviceScaleFactor: 2 });
  const page = browser.context.pages()[0] ?? (await browser.context.newPage());
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  await page.goto(url, { waitUntil: 'load', timeout: 30_000 });
  await page.waitForFunction(() => document.getElementById('verdict').textContent === 'Interrupted', null, { timeout: 30_000 });
  seen.reasons = await page.$$eval('#reasons li', (n) => n.map((e) => e.textContent));
  await page.waitForTimeout(3000);
  seen.beforeConfirm = receivedSinceRestart();
  seen.stillIdle = await page.locator('#progress').innerText();
  await shot(page, '16-interrupted');

  if (!await page.$eval('#token-card', (d) => d.open)) await page.click('#token-card summary');
  await page.fill('#token', token);
  await page.click('#check');
  await page.waitForSelector('#confirm-run:not([hidden])');
  seen.confirm = await page.locator('#confirm-run-text').innerText();
  await shot(page, '16b-confirm-check');
  await page.click('#confirm-run-yes');
  const confirmed = Date.now();
  while (!receivedSinceRestart().some((k) => CONTACT.includes(k))) {
    if (Date.now() - confirmed > 30_000) throw new Error('the lower computer heard nothing after the confirmation');
    await page.waitForTimeout(100);
  }
  seen.heardAfterMs = Date.now() - confirmed;
  seen.afterConfirm = receivedSinceRestart().filter((k) => k !== 'GET_STATE').slice(0, 4);
} catch (error) {
  problems.push(`the browser failed: ${error.stack ?? error}`);
} finally {
  if (browser) await browser.close();
}
const early = (seen.beforeConfirm || []).filter((k) => CONTACT.includes(k));
if (early.length) problems.push(`the lower computer got ${early.join(', ')} before anyone confirmed`);
console.log(JSON.stringify({ url, seen, problems }));
for (const problem of problems) console.error(`serve-crash.mjs: ${problem}`);
process.exit(problems.length === 0 ? 0 : 1);
