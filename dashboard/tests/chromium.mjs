// Debian's chromium, headless, for the dashboard's browser test and scripts/dashboard-cost.sh.
import { existsSync } from 'node:fs';
import { createRequire } from 'node:module';

export const chromiumPath = process.env.FACECAP_CHROMIUM ?? '/usr/bin/chromium';

// Why the browser cannot run here, or '' when it can.
export function missingBrowser() {
  if (!existsSync(chromiumPath))
    return `no chromium at ${chromiumPath} (Debian package chromium; scripts/quickstart.sh test installs it)`;
  try {
    createRequire(import.meta.url)('playwright-core');
  } catch {
    return 'playwright-core is not installed in dashboard/node_modules (the build runs npm ci there)';
  }
  return '';
}

// extraArgs: more chromium switches (e.g. --host-resolver-rules for a DNS-rebinding test).
export function launchChromium(extraArgs = []) {
  const { chromium } = createRequire(import.meta.url)('playwright-core');
  return chromium.launch({
    executablePath: chromiumPath,
    headless: true,
    // As root in a container: no sandbox. No background traffic on a closed network.
    // WebGL through SwiftShader where there is no GPU.
    args: ['--no-sandbox', '--disable-background-networking', '--disable-component-update', '--disable-sync',
           '--no-first-run', '--use-angle=swiftshader', '--enable-unsafe-swiftshader', ...extraArgs],
  });
}
