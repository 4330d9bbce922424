// The viewer's address options, parsed without touching the page (runner/viewer/static/viewer.js uses
// it; tests/runner/viewer/test_query.py runs it under Node):
//   ?show=optimized,plain,reference   which motions are shown (the others are hidden); "none": none.
//                                     It does not touch the keyframes and contacts checkboxes.
//   ?hide=keyframes,contacts          untick those overlays ("ghosts" is the same as "keyframes").
//   ?t=SECONDS                        start time, clamped to the motions' time range.
export const MOTIONS = ['optimized', 'plain', 'reference'];
export const OVERLAYS = ['keyframes', 'contacts'];

const list = (text) => (text || '').split(',').map((s) => s.trim().toLowerCase()).filter((s) => s);

// search: the address's query string ("?show=plain&t=1"). t0, t1: the time range [s].
// Returns { motions: {name: bool} or null (no ?show: the page's defaults), overlays: {name: false} for the
// hidden ones, time: seconds or null, unknown: names that were not understood }.
export function parseQuery(search, t0, t1) {
  const params = new URLSearchParams(search);
  const out = { motions: null, overlays: {}, time: null, unknown: [] };
  if (params.has('show')) {
    const on = list(params.get('show'));
    out.motions = Object.fromEntries(MOTIONS.map((m) => [m, on.includes(m)]));
    // the overlay names an older address may list here are accepted and change nothing
    out.unknown.push(...on.filter((n) => !MOTIONS.includes(n) && n !== 'none'
                                         && !OVERLAYS.includes(n) && n !== 'ghosts'));
  }
  for (const name of list(params.get('hide'))) {
    const key = name === 'ghosts' ? 'keyframes' : name;
    if (OVERLAYS.includes(key)) out.overlays[key] = false;
    else out.unknown.push(name);
  }
  if (params.has('t')) {
    const t = parseFloat(params.get('t'));
    out.time = Number.isFinite(t) ? Math.min(Math.max(t, t0), t1) : t0;
  }
  return out;
}
