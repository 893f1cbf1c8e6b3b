-- wrk script for scripts/loadtest.sh: POSTs one /v1/fit body over and over and counts every
-- answer by status, with a latency histogram per status.
--
--   MULTIFIT_LOADTEST_BODY=body.json wrk -t C -c C -d 60s --timeout 60s \
--       -s scripts/loadtest.lua http://127.0.0.1:PORT/v1/fit
--
-- Run it with as many threads as connections (-t C -c C): each wrk thread then has exactly one
-- connection, so `request` and `response` alternate and the time between them is the latency of
-- that one request, which is what the per-status latencies need (wrk's own latency statistics mix
-- the slow 200s with the fast 429s). `done` prints one line `LOADTEST_JSON {...}` for the caller.

local ffi = require("ffi")
ffi.cdef [[
typedef struct { long tv_sec; long tv_nsec; } loadtest_timespec;
int clock_gettime(int clock_id, loadtest_timespec *tp);
]]
local CLOCK_MONOTONIC = 1
local ts = ffi.new("loadtest_timespec")

local function now_us()
  ffi.C.clock_gettime(CLOCK_MONOTONIC, ts)
  return tonumber(ts.tv_sec) * 1e6 + tonumber(ts.tv_nsec) / 1e3
end

local path = os.getenv("MULTIFIT_LOADTEST_BODY")
if not path then
  error("set MULTIFIT_LOADTEST_BODY to the JSON body file")
end
local file = assert(io.open(path, "rb"))
local body = file:read("*a")
file:close()

wrk.method = "POST"
wrk.body = body
wrk.headers["Content-Type"] = "application/json"

-- Latency buckets: bucket b holds latencies in [RATIO^b, RATIO^(b+1)) microseconds (2 % wide).
local RATIO = 1.02
local LOG_RATIO = math.log(RATIO)

-- Per thread (each thread runs this file in its own Lua state). Flat tables of string keys,
-- so `thread:get` can copy them: counts["429"] = n, buckets["200 512"] = n.
counts = {}
buckets = {}
local started = nil
local request_text = nil

function request()
  -- One connection per thread: the request sent now is the one the next `response` answers.
  if request_text == nil then
    request_text = wrk.format()
  end
  started = now_us()
  return request_text
end

function response(status, headers, _)
  local key = tostring(status)
  counts[key] = (counts[key] or 0) + 1
  if started then
    local us = math.max(now_us() - started, 1)
    local b = math.floor(math.log(us) / LOG_RATIO)
    local bkey = key .. " " .. b
    buckets[bkey] = (buckets[bkey] or 0) + 1
    started = nil
  end
end

-- Main state only: the threads, to collect their tables in `done`.
local threads = {}

function setup(thread)
  table.insert(threads, thread)
end

local function percentile(hist, total, p)
  -- hist: {bucket -> count}; the upper edge of the bucket holding the p-th percentile, in us.
  local keys = {}
  for b in pairs(hist) do
    table.insert(keys, b)
  end
  table.sort(keys)
  local want = math.max(1, math.ceil(total * p / 100))
  local seen = 0
  for _, b in ipairs(keys) do
    seen = seen + hist[b]
    if seen >= want then
      return RATIO ^ (b + 1)
    end
  end
  return 0
end

local function json_number(x)
  if x ~= x or x == math.huge or x == -math.huge then
    return "null"
  end
  return string.format("%.6g", x)
end

function done(summary, latency, requests)
  local total_counts = {}
  local hist = {} -- status -> {bucket -> count}
  for _, thread in ipairs(threads) do
    for status, n in pairs(thread:get("counts") or {}) do
      total_counts[status] = (total_counts[status] or 0) + n
    end
    for key, n in pairs(thread:get("buckets") or {}) do
      local status, b = key:match("^(%d+) (%-?%d+)$")
      b = tonumber(b)
      hist[status] = hist[status] or {}
      hist[status][b] = (hist[status][b] or 0) + n
    end
  end
  local parts = {}
  local function add(s)
    table.insert(parts, s)
  end
  local e = summary.errors
  add(string.format(
    '"duration_us": %d, "requests": %d, "bytes": %d, "threads": %d, ' ..
    '"errors": {"connect": %d, "read": %d, "write": %d, "status": %d, "timeout": %d}, ',
    summary.duration, summary.requests, summary.bytes, #threads,
    e.connect, e.read, e.write, e.status, e.timeout))
  add(string.format(
    '"latency_us": {"min": %s, "mean": %s, "max": %s, "stdev": %s, "p50": %s, "p90": %s, "p99": %s}, ',
    json_number(latency.min), json_number(latency.mean), json_number(latency.max),
    json_number(latency.stdev), json_number(latency:percentile(50)),
    json_number(latency:percentile(90)), json_number(latency:percentile(99))))
  local status_parts = {}
  for status, n in pairs(total_counts) do
    local h = hist[status] or {}
    local measured = 0
    for _, c in pairs(h) do
      measured = measured + c
    end
    table.insert(status_parts, string.format(
      '"%s": {"count": %d, "latency_measured": %d, "p50_us": %s, "p99_us": %s, "max_us": %s}',
      status, n, measured,
      json_number(percentile(h, measured, 50)), json_number(percentile(h, measured, 99)),
      json_number(percentile(h, measured, 100))))
  end
  add('"statuses": {' .. table.concat(status_parts, ", ") .. '}')
  io.write("LOADTEST_JSON {" .. table.concat(parts) .. "}\n")
end
