"""The Redis store's keys and server-side scripts.

Keys of one session share a Redis Cluster hash tag, ``bearings:{ID}:...``:

* ``:ckpt``: the latest checkpoint, expiring after the idle timeout (``:ckpt:frames``:
  how many frames it covers; an older checkpoint never replaces a newer one);
* ``:journal``: a list of the frames answered since that checkpoint (same expiry);
* ``:lease``: the serving worker's owner token, with a short expiry (the lease);
* ``:fence``: the fencing token of the latest tenure (a number, raised by one each time
  a worker takes the lease; same expiry as the checkpoint);
* ``:gone``: set for the idle timeout when the session is deleted, so that no worker
  takes a lease on it back.

Each script runs the fencing rule (``HOLD``, see :mod:`app.service.store.protocol`)
before it writes anything.
"""

from __future__ import annotations

# The fencing rule, shared by the scripts: 0 lost, 1 held, 2 taken back.
_HOLD = """
local function hold(base, token, fence, lease_ms, ttl_ms)
  local stored = redis.call('GET', base .. ':fence')
  if stored and tonumber(stored) ~= tonumber(fence) then return 0 end
  local holder = redis.call('GET', base .. ':lease')
  if holder == token then return 1 end
  if holder or redis.call('EXISTS', base .. ':gone') == 1 then return 0 end
  redis.call('SET', base .. ':lease', token, 'PX', lease_ms)
  redis.call('SET', base .. ':fence', fence, 'PX', ttl_ms)
  return 2
end
"""

# KEYS: base; ARGV: token, lease_ms, ttl_ms. The fencing token, or 0 (held by another).
ACQUIRE = """
local base, token = KEYS[1], ARGV[1]
local holder = redis.call('GET', base .. ':lease')
local fence = redis.call('GET', base .. ':fence')
if holder == token and fence then
  redis.call('PEXPIRE', base .. ':lease', ARGV[2])
  return tonumber(fence)
end
if holder then return 0 end
redis.call('SET', base .. ':lease', token, 'PX', ARGV[2])
fence = redis.call('INCR', base .. ':fence')
redis.call('PEXPIRE', base .. ':fence', ARGV[3])
return fence
"""

# KEYS: base per session; ARGV: token, lease_ms, ttl_ms, then a fencing token each.
RENEW = (
    _HOLD
    + """
local out = {}
for i, base in ipairs(KEYS) do
  out[i] = hold(base, ARGV[1], ARGV[i+3], ARGV[2], ARGV[3])
  if out[i] == 1 then redis.call('PEXPIRE', base .. ':lease', ARGV[2]) end
end
return out
"""
)

# KEYS: base per session; ARGV: token.
RELEASE = """
for _, base in ipairs(KEYS) do
  if redis.call('GET', base .. ':lease') == ARGV[1] then redis.call('DEL', base .. ':lease') end
end
return 0
"""

# KEYS: base per session; ARGV: token, lease_ms, ttl_ms, then (data, frames, fence) each.
# A checkpoint older than the stored one (two writes overtaking each other) is ignored.
SAVE = (
    _HOLD
    + """
local out = {}
for i, base in ipairs(KEYS) do
  local ckpt, journal = base .. ':ckpt', base .. ':journal'
  if hold(base, ARGV[1], ARGV[3*i+3], ARGV[2], ARGV[3]) > 0 then
    local frames = tonumber(ARGV[3*i+2])
    local stored = tonumber(redis.call('GET', ckpt .. ':frames') or '-1')
    if frames >= stored then
      redis.call('SET', ckpt, ARGV[3*i+1], 'PX', ARGV[3])
      redis.call('SET', ckpt .. ':frames', frames, 'PX', ARGV[3])
      while true do
        local head = redis.call('LINDEX', journal, 0)
        if not head then break end
        local seq = tonumber(string.match(head, '^(%d+)|'))
        if seq == nil or seq > frames then break end
        redis.call('LPOP', journal)
      end
    end
    redis.call('PEXPIRE', journal, ARGV[3])
    redis.call('PEXPIRE', base .. ':fence', ARGV[3])
    out[i] = 1
  else out[i] = 0 end
end
return out
"""
)

# KEYS: base per entry; ARGV: token, lease_ms, ttl_ms, then (fence, entry) each. An
# entry is written only if the stored frames end right before it; one they already
# cover (a checkpoint packed after its step landed first) needs no writing; else 3, a gap.
APPEND = (
    _HOLD
    + """
local out = {}
for i, base in ipairs(KEYS) do
  local ckpt, journal = base .. ':ckpt', base .. ':journal'
  local entry = ARGV[2*i+3]
  out[i] = hold(base, ARGV[1], ARGV[2*i+2], ARGV[2], ARGV[3])
  if out[i] > 0 then
    local last = tonumber(redis.call('GET', ckpt .. ':frames') or '-1')
    local tail = redis.call('LINDEX', journal, -1)
    if tail then last = math.max(last, tonumber(string.match(tail, '^(%d+)|'))) end
    local seq = tonumber(string.match(entry, '^(%d+)|'))
    if last == seq - 1 then
      redis.call('RPUSH', journal, entry)
      redis.call('PEXPIRE', journal, ARGV[3])
      redis.call('PEXPIRE', ckpt, ARGV[3])
      redis.call('PEXPIRE', ckpt .. ':frames', ARGV[3])
      redis.call('PEXPIRE', base .. ':fence', ARGV[3])
      out[i] = 1
    elseif seq <= last then out[i] = 1  -- stored already (a checkpoint overtook it)
    else out[i] = 3 end
  end
end
return out
"""
)


def base_key(session_id: str) -> str:
    """The prefix of every key of the session (with its hash tag)."""
    return f"bearings:{{{session_id}}}"


def session_keys(session_id: str) -> list[str]:
    """Every key a session has, for deleting it."""
    base = base_key(session_id)
    return [f"{base}:{part}" for part in ("lease", "ckpt", "ckpt:frames", "journal", "fence")]


def ms(seconds: float) -> int:
    """Seconds as whole milliseconds, at least one (Redis expiries)."""
    return max(1, round(seconds * 1000))
