// What the browser tests share: Debian's Chromium, headless, with a fresh
// profile for every launch (nothing from an earlier run can affect this one).

import { chromium } from 'playwright-core';
import { mkdtempSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { join } from 'node:path';

const CHROMIUM = '/usr/bin/chromium';
// Without the background-networking flags Chromium keeps trying to reach
// Google's hosts, which this machine's closed network refuses.
const ARGS = [
  '--headless',
  '--no-sandbox',
  '--disable-gpu',
  '--disable-quic',
  '--no-first-run',
  '--disable-background-networking',
  '--disable-component-update',
  '--disable-sync',
];

/** Launches Chromium with `options` (viewport, touch, ...); returns the
 *  context and a `close()` that also removes the profile. */
export async function launch(options) {
  const userDataDir = mkdtempSync(join(tmpdir(), 'groundcal-chromium-'));
  try {
    const context = await chromium.launchPersistentContext(userDataDir, {
      executablePath: CHROMIUM,
      headless: true,
      args: ARGS,
      timeout: 60_000,
      ...options,
    });
    const close = async () => {
      await context.close();
      rmSync(userDataDir, { recursive: true, force: true });
    };
    return { context, close };
  } catch (error) {
    rmSync(userDataDir, { recursive: true, force: true });
    throw error;
  }
}

/** Ends the script after `seconds`: a hung browser must not hang the tests. */
export function deadline(script, seconds) {
  setTimeout(() => {
    console.error(`${script}: timed out after ${seconds} s`);
    process.exit(1);
  }, seconds * 1000).unref();
}
