// Two devices on one daemon (tests/serve_browser.rs): a phone (390×844) and
// a pad (1024×768) show the same store.
//
//   node tests/browser/serve-two.mjs URL TOKEN SCREENSHOT_DIR FIRST_ID SECOND_ID
//
// Both pages open with no calibration active. On the phone, "Make active"
// on FIRST_ID (confirmed): the pad must show it Active, and no "Roll back
// to this" on it, within 2 s of the phone's answer. On the pad, "Roll back
// to this" on SECOND_ID (confirmed): the phone must show that within 2 s.
// Saves serve-14-phone.png and serve-14-pad.png. Prints one JSON line of
// what it saw; exits 0 when every check passes.

import { resolve } from 'node:path';

import { deadline, launch } from './chromium.mjs';

const [url, token, shotDir, first, second] = process.argv.slice(2);
if (!url || !token || !shotDir || !first || !second) {
  console.error('usage: node serve-two.mjs URL TOKEN SCREENSHOT_DIR FIRST_ID SECOND_ID');
  process.exit(2);
}
deadline('serve-two.mjs', 120);

const problems = [];
const seen = {};
const browsers = [];
async function open(viewport) {
  const browser = await launch({ viewport, isMobile: viewport.width < 800, hasTouch: true, deviceScaleFactor: 2 });
  browsers.push(browser);
  const page = browser.context.pages()[0] ?? (await browser.context.newPage());
  page.on('pageerror', (e) => problems.push(`page error: ${e.message}`));
  page.on('console', (m) => { if (m.type() === 'error') problems.push(`console error: ${m.text()}`); });
  await page.goto(url, { waitUntil: 'load', timeout: 30_000 });
  await page.waitForFunction(() => document.getElementById('progress').textContent === 'idle');
  await page.waitForFunction(() => document.querySelectorAll('#history button.rollback').length >= 2);
  if (!await page.$eval('#token-card', (d) => d.open)) await page.click('#token-card summary');
  await page.fill('#token', token);
  return page;
}
// Makes `id` active from `page`, confirmed; returns when the answer came.
async function activate(page, id) {
  await page.click(`#history button.rollback[data-id="${id}"]`);
  await page.waitForSelector('#confirm:not([hidden])');
  const answered = page.waitForResponse((r) => r.request().method() === 'POST' && r.ok(), { timeout: 10_000 });
  await page.click('#confirm-yes');
  await answered;
  return Date.now();
}
// How long until `page` shows `id` as the active calibration everywhere.
async function shownAfter(page, id, since) {
  await page.waitForFunction((active) => document.getElementById('active').dataset.id === active
    && /Active/.test(document.querySelector(`#history tr[title="${active}"]`)?.textContent || '')
    && !document.querySelector(`#history button.rollback[data-id="${active}"]`), id, { timeout: 10_000, polling: 50 });
  return Date.now() - since;
}
try {
  const phone = await open({ width: 390, height: 844 });
  const pad = await open({ width: 1024, height: 768 });
  const accepted = await activate(phone, first);
  seen.padAfterMs = await shownAfter(pad, first, accepted);
  const rolledBack = await activate(pad, second);
  seen.phoneAfterMs = await shownAfter(phone, second, rolledBack);
  seen.padShowsSecond = await shownAfter(pad, second, rolledBack);
  seen.phoneActive = await phone.$eval('#active', (e) => e.dataset.id);
  seen.padActive = await pad.$eval('#active', (e) => e.dataset.id);
  seen.phoneActiveText = await phone.locator('#active').innerText();
  await phone.screenshot({ path: resolve(shotDir, 'serve-14-phone.png'), fullPage: true });
  await pad.screenshot({ path: resolve(shotDir, 'serve-14-pad.png'), fullPage: true });
} catch (error) {
  problems.push(`the browser failed: ${error.stack ?? error}`);
} finally {
  for (const b of browsers) await b.close();
}
for (const key of ['padAfterMs', 'phoneAfterMs']) {
  if (!(seen[key] <= 2000)) problems.push(`${key}: the other device showed the change after ${seen[key]} ms`);
}
console.log(JSON.stringify({ url, seen, problems }));
for (const problem of problems) console.error(`serve-two.mjs: ${problem}`);
process.exit(problems.length === 0 ? 0 : 1);
