// Keeps `browsers` headless chromium processes on the dashboard's live view for `seconds`
// (scripts/dashboard-cost.sh): each a separate browser, as two operators' screens would be.
// Prints how many stream frames each page drew, so a run that drew nothing is seen.
// Usage: node dashboard/tests/attach.mjs URL SECONDS BROWSERS
import { launchChromium } from './chromium.mjs';

const [url, seconds, count] = [process.argv[2], Number(process.argv[3]), Number(process.argv[4] ?? 2)];
const browsers = await Promise.all(Array.from({ length: count }, () => launchChromium()));
const pages = await Promise.all(browsers.map(async (b) => {
  const page = await b.newPage({ viewport: { width: 1280, height: 800 } });
  await page.goto(url);
  return page;
}));
console.log('attached');
await new Promise((r) => setTimeout(r, seconds * 1000));
const frames = await Promise.all(pages.map((p) => p.evaluate(() => Number(document.body.dataset.frames ?? 0))));
console.log(`frames drawn per page: ${frames.join(', ')}`);
await Promise.all(browsers.map((b) => b.close()));
