# subdivd — build, test, benchmark. See README.md.
CC      ?= cc
CXX     ?= g++
CFLAGS  ?= -O2 -g
# -ffp-contract=off: no fused multiply-adds, whatever the compiler or target (every row of S sums
# the same bytes in the level build, in core/direct.c and in edits; DECISIONS 50)
override CFLAGS += -std=c11 -D_GNU_SOURCE -ffp-contract=off -Wall -Wextra -Werror -fPIC
LDLIBS  += -llapacke -llapack -lm
API_LIBS := $(shell pkg-config --libs jansson zlib 2>/dev/null || echo -ljansson -lz)
SRV_LIBS := $(shell pkg-config --libs libmicrohttpd sqlite3 nettle hiredis 2>/dev/null || echo -lmicrohttpd -lsqlite3 -lnettle -lhiredis) -lpthread
PYTHON  ?= /usr/bin/python3
B       := build

CORE_SRC := $(wildcard core/*.c)
CORE_OBJ := $(patsubst %.c,$(B)/%.o,$(CORE_SRC))
CORE_LIB := $(B)/libsubdiv.a

.PHONY: all test test-paraview bench soak sanitize fuzz run deps clean clean-build
all: $(CORE_LIB) $(B)/sdlevel $(B)/test_core

$(B)/%.o: %.c $(wildcard core/*.h)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -c $< -o $@

# Archives are written afresh: `ar r` alone keeps the members of deleted sources.
$(CORE_LIB): $(CORE_OBJ)
	rm -f $@ && ar rcs $@ $^

# api/: JSON mapping and output writers (no HTTP)
API_SRC := $(wildcard api/*.c)
API_OBJ := $(patsubst %.c,$(B)/%.o,$(API_SRC))
API_LIB := $(B)/libsubdivapi.a
$(B)/api/%.o: api/%.c $(wildcard api/*.h) $(wildcard core/*.h)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -c $< -o $@
$(API_LIB): $(API_OBJ)
	rm -f $@ && ar rcs $@ $^

$(B)/sdlevel: tests/tools/sdlevel.c tests/tools/textmesh.c tests/tools/textmesh.h $(CORE_LIB)
	$(CC) $(CFLAGS) tests/tools/sdlevel.c tests/tools/textmesh.c $(CORE_LIB) $(LDLIBS) -o $@

TEST_SRC := $(wildcard tests/core/*.c)
$(B)/test_core: $(TEST_SRC) $(CORE_LIB) $(wildcard tests/core/*.h)
	$(CC) $(CFLAGS) $(TEST_SRC) $(CORE_LIB) $(LDLIBS) -o $@

# web/: the front end served at / (npm + esbuild into $(B)/web; defines WEB_LIST)
include web/Makefile.inc

# server/: the daemon (and the offline `subdivd refine`), with embedded OpenAPI + web files.
# Assets are URLPATH|CONTENT_TYPE|CACHE_CONTROL|FILE (tools/embed.c); the built web front end
# lists its own in $(WEB_LIST) (web/Makefile.inc), one per line, since its names carry hashes.
SRV_SRC := $(wildcard server/*.c)
SRV_OBJ := $(patsubst %.c,$(B)/%.o,$(SRV_SRC)) $(B)/assets.o $(B)/errors.o
ASSETS  := /v1/openapi.json|application/json|no-cache|api/openapi.json
$(B)/server/%.o: server/%.c $(wildcard server/*.h) $(wildcard api/*.h) $(wildcard core/*.h)
	@mkdir -p $(dir $@)
	$(CC) $(CFLAGS) -c $< -o $@
$(B)/embed: tools/embed.c
	@mkdir -p $(B)
	$(CC) -O1 -o $@ $<
$(B)/assets.c: $(B)/embed api/openapi.json $(WEB_LIST)
	$(B)/embed $@ $(foreach a,$(ASSETS),'$(a)') $$(cat $(WEB_LIST))
$(B)/assets.o: $(B)/assets.c server/server.h
	$(CC) $(CFLAGS) -Wno-overlength-strings -c $< -o $@
# the pages of GET /errors/<slug>, from the one table of problem types (docs/SERVICE.md "Errors")
$(B)/errors.c: tools/errors.awk docs/SERVICE.md
	@mkdir -p $(B)
	awk -f tools/errors.awk docs/SERVICE.md > $@.tmp && mv $@.tmp $@
$(B)/errors.o: $(B)/errors.c server/errors.h
	$(CC) $(CFLAGS) -c $< -o $@
$(B)/subdivd: $(SRV_OBJ) $(API_LIB) $(CORE_LIB)
	$(CC) $(CFLAGS) $(SRV_OBJ) $(API_LIB) $(CORE_LIB) $(API_LIBS) $(SRV_LIBS) $(LDLIBS) -o $@

# mpi/: subdivd-mpi, one level refined by several MPI processes (docs/BATCH.md), built with
# Open MPI's mpicc and METIS (tools/packages.txt); `make all` builds it when mpicc is there.
MPICC   ?= mpicc
MPI_SRC := $(wildcard mpi/*.c)
$(B)/subdivd-mpi: $(MPI_SRC) mpi/mp.h tests/tools/textmesh.c tests/tools/textmesh.h $(API_LIB) $(CORE_LIB)
	$(MPICC) $(CFLAGS) $(MPI_SRC) tests/tools/textmesh.c $(API_LIB) $(CORE_LIB) -lmetis $(API_LIBS) -lpthread $(LDLIBS) -o $@
ifneq ($(shell command -v $(MPICC) 2>/dev/null),)
EXTRA_ALL += $(B)/subdivd-mpi
endif

-include tests/peers/Makefile.inc
-include tests/tools/Makefile.inc
-include tests/fuzz/Makefile.inc
-include tests/api/Makefile.inc
-include tetgen/Makefile.inc
-include clients/python/Makefile.inc
all: $(API_LIB) $(B)/subdivd $(EXTRA_ALL)
-include bench/Makefile.inc

deps:
	@sh tools/deps.sh

# Starts the daemon on localhost:8080 (web front end at /, API under /v1, OpenAPI at
# /v1/openapi.json). Flags: make run ARGS="--port 9000 --log-level debug".
# Sessions are kept in $(DATA)/sessions.db (SQLite): they survive a restart of `make run`.
DATA ?= data
run: deps
	$(MAKE) all
	@mkdir -p $(DATA)
	@echo "subdivd: sessions in $(DATA)/sessions.db; open the address it prints below (http://127.0.0.1:8080/ unless ARGS says otherwise; the API document at /v1/openapi.json); Ctrl-C stops it"
	./$(B)/subdivd --store sqlite:$(DATA)/sessions.db $(ARGS)

# Runs every suite and ends with one line: "N passed, N failed".
test: deps
	$(MAKE) all $(OSD_LOOP)
	@sh tests/run_all.sh

# ParaView itself opens our VTU (raw and zlib), legacy VTK and a PVD series of examples/mixed.json
# (tests/paraview/check.py). Not part of `make test` or CI: Debian's paraview is a large install,
# done here when pvpython is missing (apt-get needs root).
PV_DIR := $(B)/paraview
test-paraview: all
	@command -v pvpython >/dev/null 2>&1 || DEBIAN_FRONTEND=noninteractive apt-get install -y --no-install-recommends paraview python3-paraview
	rm -rf $(PV_DIR) && mkdir -p $(PV_DIR)
	./$(B)/subdivd refine examples/mixed.json --level 2 -o $(PV_DIR)/level.vtu
	./$(B)/subdivd refine examples/mixed.json --level 2 --compress zlib --names true -o $(PV_DIR)/level_z.vtu
	./$(B)/subdivd refine examples/mixed.json --level 2 -o $(PV_DIR)/level.vtk
	SUBDIVD=$(B)/subdivd ./$(B)/subdiv refine examples/mixed.json --level 2 --pvd $(PV_DIR)/series --spawn -q
	pvpython tests/paraview/check.py examples/mixed.json 2 $(PV_DIR)

sanitize: deps
	$(MAKE) all $(OSD_LOOP)  # the tools the suites run from build/ (subdiv, the OpenSubdiv peer, subdivd-mpi)
	$(MAKE) clean-build B=build-asan
	$(MAKE) all B=build-asan CFLAGS="-O1 -g -fsanitize=address,undefined -fno-omit-frame-pointer -fno-sanitize-recover=all" LDLIBS="$(LDLIBS) -fsanitize=address,undefined"
	SD_SANITIZE=1 SDLEVEL=build-asan/sdlevel TEST_CORE=build-asan/test_core SUBDIVD=build-asan/subdivd FUZZ_API=build-asan/fuzz_api FUZZ_PACKED=build-asan/fuzz_packed FUZZ_HTTP=build-asan/fuzz_http API_FAULTS=build-asan/api_faults PACKED_PARSE=build-asan/packed_parse SLOTS_TEST=build-asan/slots_test KEEP_TEST=build-asan/keep_test PERSIST_REDIS_TEST=build-asan/persist_redis_test sh tests/run_all.sh

clean-build:
	rm -rf $(B)

clean:
	rm -rf build build-asan build-fuzz
