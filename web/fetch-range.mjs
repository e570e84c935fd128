// Byte ranges of a URL by HTTP range requests (RFC 9110 section 14): `Range: bytes=a-b`,
// answered by 206 Partial Content. A server that ignores the header answers 200 with the
// whole file; that still works (the part is cut out) but fetches everything, so it is an
// error unless `allowWhole` is set (the first request says so to the user).

/** Fetches `length` bytes at `offset`; returns {bytes, fetched} (fetched: body bytes received). */
export async function fetchRange(url, offset, length, allowWhole = false) {
  if (length === 0) return { bytes: new Uint8Array(0), fetched: 0 };
  const res = await fetch(url, { headers: { Range: `bytes=${offset}-${offset + length - 1}` } });
  if (res.status !== 206 && !(res.status === 200 && allowWhole)) {
    // not the part asked for (the whole file, or an error): not read
    await res.body?.cancel().catch(() => {});
    const e = new Error(
      res.status === 200
        ? `${url}: the server ignores range requests (answered 200 with the whole file); host the file on a server with range support`
        : `${url}: HTTP ${res.status} ${res.statusText}`,
    );
    e.fetched = 0;
    throw e;
  }
  const body = new Uint8Array(await res.arrayBuffer());
  if (res.status === 206) {
    if (body.length !== length) {
      const e = new Error(`${url}: asked for ${length} bytes at ${offset}, got ${body.length}`);
      e.fetched = body.length;
      throw e;
    }
    const range = res.headers.get('Content-Range');
    if (range !== null && !range.startsWith(`bytes ${offset}-${offset + length - 1}/`)) {
      const e = new Error(`${url}: asked for bytes ${offset}-${offset + length - 1}, got ${range}`);
      e.fetched = body.length;
      throw e;
    }
    return { bytes: body, fetched: body.length };
  }
  // 200 with allowWhole: cut the part out of the whole file
  if (body.length < offset + length) throw new Error(`${url}: the file is shorter than its header says`);
  return { bytes: body.subarray(offset, offset + length), fetched: body.length };
}
