/* probe.c — the health probe `subdivd --healthcheck [URL]` (see probe.h).
 *
 * A deliberately tiny HTTP/1.0 client: plain http only, host as a name or an IPv4/IPv6 literal
 * ("[::1]"), 5 s timeouts on connect, send and receive. It reads the status line and nothing
 * else: 200 is healthy. Used as the Docker HEALTHCHECK, where the image carries no curl.
 */
#include "probe.h"
#include <netdb.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

int probe_main(const char *url)
{
    if (!url)
        url = PROBE_DEFAULT_URL;
    if (strncmp(url, "http://", 7)) {
        fprintf(stderr, "subdivd --healthcheck: %s: only http://HOST[:PORT]/PATH URLs\n", url);
        return 2;
    }
    char host[256], port[16] = "80", path[1024] = "/";
    const char *h = url + 7, *slash = strchr(h, '/');
    size_t hl = slash ? (size_t)(slash - h) : strlen(h);
    if (slash)
        snprintf(path, sizeof path, "%s", slash);
    if (!hl || hl >= sizeof host) {
        fprintf(stderr, "subdivd --healthcheck: %s: no host\n", url);
        return 2;
    }
    memcpy(host, h, hl);
    host[hl] = 0;
    char *colon = host[0] == '[' ? strstr(host, "]:") : strrchr(host, ':');
    if (colon) {
        if (host[0] == '[')
            colon++;
        snprintf(port, sizeof port, "%s", colon + 1);
        *colon = 0;
    }
    if (host[0] == '[') { /* [v6 literal] */
        memmove(host, host + 1, strlen(host));
        char *e = strchr(host, ']');
        if (e)
            *e = 0;
    }
    struct addrinfo hints = {0}, *res = NULL;
    hints.ai_socktype = SOCK_STREAM;
    int rc = getaddrinfo(host, port, &hints, &res);
    if (rc) {
        fprintf(stderr, "subdivd --healthcheck: %s: %s\n", host, gai_strerror(rc));
        return 1;
    }
    int fd = -1;
    for (struct addrinfo *a = res; a && fd < 0; a = a->ai_next) {
        fd = socket(a->ai_family, a->ai_socktype | SOCK_CLOEXEC, a->ai_protocol);
        if (fd < 0)
            continue;
        struct timeval tv = {5, 0};
        setsockopt(fd, SOL_SOCKET, SO_RCVTIMEO, &tv, sizeof tv);
        setsockopt(fd, SOL_SOCKET, SO_SNDTIMEO, &tv, sizeof tv);
        if (connect(fd, a->ai_addr, a->ai_addrlen)) {
            close(fd);
            fd = -1;
        }
    }
    freeaddrinfo(res);
    if (fd < 0) {
        fprintf(stderr, "subdivd --healthcheck: cannot connect to %s port %s\n", host, port);
        return 1;
    }
    char req[1400];
    int n = snprintf(req, sizeof req, "GET %s HTTP/1.0\r\nHost: %s\r\nConnection: close\r\n\r\n",
                     path, host);
    char line[128] = "";
    ssize_t got = 0;
    if (send(fd, req, (size_t)n, MSG_NOSIGNAL) == n)
        got = recv(fd, line, sizeof line - 1, 0);
    close(fd);
    line[got > 0 ? got : 0] = 0;
    line[strcspn(line, "\r\n")] = 0;
    int status = 0;
    if (sscanf(line, "HTTP/%*d.%*d %d", &status) == 1 && status == 200) {
        printf("ok: %s\n", url);
        return 0;
    }
    fprintf(stderr, "subdivd --healthcheck: %s: %s\n", url, line[0] ? line : "no answer");
    return 1;
}
