/* probe.h — `subdivd --healthcheck [URL]`: one HTTP GET, exit 0 on a 200 answer, else 1.
 * For Docker's HEALTHCHECK: the runtime image has no curl. */
#ifndef SUBDIVD_PROBE_H
#define SUBDIVD_PROBE_H

#define PROBE_DEFAULT_URL "http://127.0.0.1:8080/healthz"

/* Returns the process exit code; prints one line (stdout: ok, stderr: why not). */
int probe_main(const char *url);

#endif
