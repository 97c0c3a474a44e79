# Sourced by the bench-hosts*.sh scripts: two network namespaces "$a" and "$b" joined by a veth
# pair (10.77.0.1/24 in a, 10.77.0.2/24 in b), the README's two-machine set-up on one machine.
# two_hosts_up creates them; two_hosts_down removes them (call it from the script's EXIT trap).
# fly_hosts HOSTS LOG DAEMON_LOG TEAM LAUNCH_ARGS...: one `launch` in a (HOSTS = 1), or over both
# (HOSTS = 2) with a daemon in b that has its own /dev/shm, so only the network joins the halves.
two_hosts_up() {
  ip netns add "$a"; ip netns add "$b"
  ip -n "$a" link add veth0 type veth peer name veth1 netns "$b"
  ip -n "$a" addr add 10.77.0.1/24 dev veth0; ip -n "$b" addr add 10.77.0.2/24 dev veth1
  for x in "$a veth0" "$b veth1" "$a lo" "$b lo"; do ip -n "${x% *}" link set "${x#* }" up; done
}
two_hosts_down() { ip netns del "$a" 2>/dev/null || true; ip netns del "$b" 2>/dev/null || true; }
daemon_in_b() { # TEAM DAEMON_LOG: a daemon in b, in the background
  ip netns exec "$b" unshare --mount sh -c 'mount -t tmpfs tmpfs /dev/shm && exec "$0" "$@"' \
    "$bin" host --connect tcp/10.77.0.1:7447 --team "$1" --quiet > "$2" 2>&1 &
}
fly_hosts() {
  _hosts=$1 _log=$2 _dlog=$3 _team=$4; shift 4
  if [ "$_hosts" = 1 ]; then
    ip netns exec "$a" "$bin" launch --team "$_team" "$@" > "$_log" 2>&1 || true
  else
    daemon_in_b "$_team" "$_dlog"
    ip netns exec "$a" "$bin" launch --team "$_team" "$@" --hosts 2 \
      --listen tcp/10.77.0.1:7447 > "$_log" 2>&1 || true
    wait
  fi
}
