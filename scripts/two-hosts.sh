# Sourced by the bench-hosts*.sh scripts: two network namespaces "$a" and "$b" joined by a veth
# pair (10.77.0.1/24 in a, 10.77.0.2/24 in b), the README's two-machine set-up on one machine.
# two_hosts_up creates them and the team's keys (`keys new`, in a temporary directory);
# two_hosts_down removes both (call it from the script's EXIT trap).
# fly_hosts HOW LOG DAEMON_LOG TEAM LAUNCH_ARGS...: one `launch` in a (HOW = 1), or over both
# with a daemon in b that has its own /dev/shm, so only the network joins the halves: HOW = tls
# (mutual TLS with the keys), tcp (plain TCP, --insecure) or 2 (tls). Binaries from before TLS
# (no `keys` command, e.g. a BEFORE_BIN) fly plain TCP as they did, whatever HOW says.
two_hosts_up() {
  ip netns add "$a"; ip netns add "$b"
  ip -n "$a" link add veth0 type veth peer name veth1 netns "$b"
  ip -n "$a" addr add 10.77.0.1/24 dev veth0; ip -n "$b" addr add 10.77.0.2/24 dev veth1
  for x in "$a veth0" "$b veth1" "$a lo" "$b lo"; do ip -n "${x% *}" link set "${x#* }" up; done
  _keys=$(mktemp -d)
  if "$bin" keys --help > /dev/null 2>&1; then "$bin" keys new "$_keys/team" > /dev/null; fi
}
two_hosts_down() {
  ip netns del "$a" 2>/dev/null || true; ip netns del "$b" 2>/dev/null || true
  if [ -n "${_keys:-}" ]; then rm -rf "$_keys"; fi
}
link_args() { # HOW: sets listen_args and connect_args
  if [ ! -d "$_keys/team" ]; then
    listen_args="--listen tcp/10.77.0.1:7447" connect_args="--connect tcp/10.77.0.1:7447"
  elif [ "$1" = tcp ]; then
    listen_args="--listen tcp/10.77.0.1:7447 --insecure"
    connect_args="--connect tcp/10.77.0.1:7447 --insecure"
  else
    listen_args="--listen tls/10.77.0.1:7447 --keys $_keys/team/orchestrator"
    connect_args="--connect tls/10.77.0.1:7447 --keys $_keys/team/host-1"
  fi
}
daemon_in_b() { # TEAM DAEMON_LOG: a daemon in b, in the background (link_args first)
  ip netns exec "$b" unshare --mount sh -c 'mount -t tmpfs tmpfs /dev/shm && exec "$0" "$@"' \
    "$bin" host $connect_args --team "$1" --quiet > "$2" 2>&1 &
}
fly_hosts() {
  _how=$1 _log=$2 _dlog=$3 _team=$4; shift 4
  if [ "$_how" = 1 ]; then
    ip netns exec "$a" "$bin" launch --team "$_team" "$@" > "$_log" 2>&1 || true
  else
    link_args "$_how"
    daemon_in_b "$_team" "$_dlog"
    ip netns exec "$a" "$bin" launch --team "$_team" "$@" --hosts 2 \
      $listen_args > "$_log" 2>&1 || true
    wait
  fi
}
