// tests/bench/web_attach.mjs — one browser on a run's live view, for bench_web.sh: opens the
// page in headless Chromium (Debian's, driven by puppeteer-core, as the browser tests do),
// stays until the page says the run ended, and prints what the page received and drew
// ("samples N frames N").
//   node web_attach.mjs URL [TIMEOUT_S]
import { launchBrowser } from '../media/web/browser_support.mjs';

const [url, timeoutS = '120'] = process.argv.slice(2);
const { browser, page } = await launchBrowser();
try {
  await page.goto(url, {waitUntil: 'load'});
  await page.waitForFunction(() => window.omnitwinView && window.omnitwinView.ended,
                             {timeout: Number(timeoutS) * 1000, polling: 200});
  const v = await page.evaluate(() => ({samples: window.omnitwinView.samples, frames: window.omnitwinView.frames}));
  console.log(`samples ${v.samples} frames ${v.frames}`);
} finally {
  await browser.close();
}
