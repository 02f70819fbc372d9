// The dashboard's build: three pages (the live view, the replay page and the login page) with relative asset
// paths, so facecapd can serve the output directory at "/" (docs/dashboard.md).
// `npm run build -- --outDir DIR` builds elsewhere (CMake builds into the build tree).
import { resolve } from 'node:path';
import { defineConfig } from 'vite';

export default defineConfig({
  base: './',
  build: {
    outDir: 'dist',
    emptyOutDir: true,
    chunkSizeWarningLimit: 1024,
    rollupOptions: {
      input: {
        live: resolve(import.meta.dirname, 'index.html'),
        replay: resolve(import.meta.dirname, 'replay.html'),
        login: resolve(import.meta.dirname, 'login.html'),
      },
    },
  },
});
