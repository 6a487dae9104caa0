#!/usr/bin/env bash
# deploy/cluster/make-nats-certs.sh OUT_DIR NATS_NODES MAPPER_HOSTS [GATEWAYS]
#
# The certificates of a levelmap cluster's NATS servers and of the mapper hosts that use them
# (docs/cluster.md), both sides authenticated, and the servers' authorization:
#
#   OUT_DIR/ca.pem, ca.key          the certificate authority (ca.key stays off the hosts)
#   OUT_DIR/NODE.pem, NODE.key      one per NATS server (NATS_NODES, comma-separated): its
#                                   clients' TLS and its cluster routes (server and client use)
#   OUT_DIR/HOST.pem, HOST.key      one per mapper host (MAPPER_HOSTS, comma-separated);
#                                   common name = the host's name
#   OUT_DIR/GATEWAY.pem, .key       one per HTTP gateway (GATEWAYS, comma-separated, optional)
#   OUT_DIR/auth.conf               `include`d by every server's config: each mapper host's
#                                   certificate maps to a user (verify_and_map) allowed the
#                                   JetStream API and the site logs, leases and snapshots;
#                                   each gateway's to a user who may read the leases and the
#                                   streams' info, and no record; nobody else is a user
#
# A client without a certificate of this CA cannot connect; one with a certificate of this CA
# for a name not in MAPPER_HOSTS connects to no user and is refused. Run again with more hosts:
# the CA and the certificates already made are kept, auth.conf is written anew for exactly the
# hosts named (the servers read it at start or on `nats-server --signal reload`).
#
# Environment (MAKE_CERTS_…: the services read every LEVELMAP_<KEY> as a config key):
#   MAKE_CERTS_NATS_NAMES  comma-separated DNS names and IP addresses the hosts dial the
#                          servers by, put in each server's certificate beside its node name,
#                          localhost and 127.0.0.1
#   MAKE_CERTS_DAYS        validity of new certificates in days (default 825)
# Needs bash and openssl.
set -euo pipefail

[ $# -eq 3 ] || [ $# -eq 4 ] || {
  echo "usage: $0 OUT_DIR NATS_NODES MAPPER_HOSTS [GATEWAYS] (lists comma-separated)" >&2
  exit 2
}
command -v openssl >/dev/null || {
  echo "$0: openssl is not installed" >&2
  exit 1
}
out="$1"
IFS=, read -r -a nodes <<<"$2"
IFS=, read -r -a hosts <<<"$3"
IFS=, read -r -a gateways <<<"${4:-}"
days="${MAKE_CERTS_DAYS:-825}"
for name in "${nodes[@]}" "${hosts[@]}" "${gateways[@]}"; do
  [[ "$name" =~ ^[A-Za-z0-9_-]+$ ]] || {
    echo "$0: '$name': names are [A-Za-z0-9_-]+" >&2
    exit 2
  }
done
if [ "$(printf '%s\n' "${nodes[@]}" "${hosts[@]}" "${gateways[@]}" | sort | uniq -d)" != "" ]; then
  echo "$0: a name is given twice" >&2
  exit 2
fi
mkdir -p "$out"
cd "$out"

if [ ! -f ca.pem ]; then
  openssl req -x509 -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -days "$days" \
    -subj "/CN=levelmap NATS CA" -keyout ca.key -out ca.pem 2>/dev/null
  chmod 600 ca.key
fi

# certificate NAME SAN USAGE: a key and a certificate signed by the CA.
certificate() {
  local name="$1" san="$2" usage="$3"
  [ -f "$name.pem" ] && return
  openssl req -newkey ec -pkeyopt ec_paramgen_curve:P-256 -nodes -subj "/CN=$name" \
    -keyout "$name.key" -out "$name.csr" 2>/dev/null
  printf 'subjectAltName=%s\nextendedKeyUsage=%s\n' "$san" "$usage" >"$name.ext"
  openssl x509 -req -in "$name.csr" -CA ca.pem -CAkey ca.key -CAcreateserial -days "$days" \
    -extfile "$name.ext" -out "$name.pem" 2>/dev/null
  rm -f "$name.csr" "$name.ext"
  chmod 600 "$name.key"
}

extra=""
IFS=, read -r -a names <<<"${MAKE_CERTS_NATS_NAMES:-}"
for n in "${names[@]}"; do
  if [[ "$n" =~ ^[0-9.]+$ || "$n" == *:* ]]; then extra+=",IP:$n"; else extra+=",DNS:$n"; fi
done
for node in "${nodes[@]}"; do
  # Routes between servers are TLS too: each server is also its peers' client.
  certificate "$node" "DNS:$node,DNS:localhost,IP:127.0.0.1$extra" "serverAuth,clientAuth"
done
for host in "${hosts[@]}" "${gateways[@]}"; do
  certificate "$host" "DNS:$host" "clientAuth"
done

# What a mapper host may do: the JetStream API, its replies, the site logs (levelmap.site.*),
# the nodes' clouds (levelmap.cloud.*), the KV buckets (leases) and object stores
# (snapshots). Users are named by their certificate's subject (verify_and_map).
{
  echo "# Written by deploy/cluster/make-nats-certs.sh; include it in every server's config."
  echo "authorization {"
  echo "  mapper_host = {"
  echo '    publish = ["$JS.API.>", "$JS.ACK.>", "$KV.>", "$O.>", "levelmap.site.>", "levelmap.cloud.>", "_INBOX.>"]'
  echo '    subscribe = ["$KV.>", "$O.>", "levelmap.site.>", "levelmap.cloud.>", "_INBOX.>"]'
  echo "  }"
  # A gateway reads who holds each site (the leases' bucket, levelmap_site_leases, as the
  # mapper names it) and whether a site's stream exists; it reads no record and writes nothing.
  # (nats-server refuses a permissions block no user refers to: written only with gateways.)
  if [ ${#gateways[@]} -gt 0 ]; then
    echo "  http_gateway = {"
    echo '    publish = ["$JS.API.INFO", "$JS.API.STREAM.INFO.>", "$JS.API.DIRECT.GET.KV_levelmap_site_leases.>", "$JS.API.STREAM.MSG.GET.KV_levelmap_site_leases"]'
    echo '    subscribe = ["_INBOX.>"]'
    echo "  }"
  fi
  echo "  users = ["
  for host in "${hosts[@]}"; do
    echo "    { user: \"CN=$host\", permissions: \$mapper_host }"
  done
  for gateway in "${gateways[@]}"; do
    echo "    { user: \"CN=$gateway\", permissions: \$http_gateway }"
  done
  echo "  ]"
  echo "}"
} >auth.conf
echo "$out: CA, ${#nodes[@]} server, ${#hosts[@]} host and ${#gateways[@]} gateway certificates, auth.conf"
