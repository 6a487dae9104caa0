#!/usr/bin/env bash
# deploy/zenoh/make-certs.sh OUT_DIR FLEET ROBOT...
#
# Each ROBOT is a robot of FLEET, or OTHER_FLEET/ROBOT for a robot of another fleet (a cluster's
# routers serve every site; robot ids are unique over them all, being certificates' names).
#
# The certificates of a deployment's Zenoh links (TLS, both sides authenticated) and the mapper's
# Zenoh configuration, with an access-control list by certificate common name:
#
#   OUT_DIR/ca.pem, ca.key          the certificate authority (ca.key stays off the robots)
#   OUT_DIR/mapper.pem, mapper.key  the mapper's certificate, for the names robots dial
#   OUT_DIR/ROBOT.pem, ROBOT.key    one per robot; common name = the robot id
#   OUT_DIR/router.json5            the mapper's [zenoh] config_file: a router on
#                                   tls/0.0.0.0:7447 requiring client certificates from this
#                                   CA, and the access-control list for the ROBOTs; on a
#                                   cluster, every mapper host's router (the routers connect
#                                   to each other with the same mapper certificate)
#
# Robot R of fleet F may put only on levelmap/F/robots/R/{node,odom,scan}, and receive only its own
# levelmap/F/robots/R/{ack,localization} and levelmap/F/map/** (and query the latter);
# the mapper's own session is the router, so acks, localizations and map data can come from
# nowhere else, or from another mapper host's router (the mapper certificate, which may pass
# anything under levelmap/). Everything else is denied, to anyone (a certificate of this CA
# with another common name included).
#
# Environment (MAKE_CERTS_…: the services read every LEVELMAP_<KEY> as a config key):
#   MAKE_CERTS_MAPPER_NAMES  comma-separated DNS names and IP addresses robots use to reach
#                            the mapper, put in its certificate beside localhost and 127.0.0.1
#                            (a robot checks the host of its tls/HOST:PORT endpoint against
#                            them)
#   MAKE_CERTS_LISTEN        the router's endpoint (default tls/0.0.0.0:7447)
#   MAKE_CERTS_DAYS          validity of new certificates in days (default 825)
#   MAKE_CERTS_DIR           the folder router.json5 names the CA and mapper files in (default
#                            OUT_DIR, absolute): where the mapper will read them, when the
#                            files are made on another machine
#
# Run again with more robots: the CA and the certificates already in OUT_DIR are kept, the
# missing ones are made, and router.json5 is written anew for exactly the robots named (one
# left out loses all access once the mapper restarts). Needs bash and openssl.
set -euo pipefail

usage() {
  echo "usage: $0 OUT_DIR FLEET ROBOT..." >&2
  exit 2
}
[ $# -ge 3 ] || usage
command -v openssl >/dev/null || {
  echo "$0: openssl is not installed" >&2
  exit 1
}
out="$1" fleet="$2"
shift 2
robots=() robot_fleets=()
for arg in "$@"; do
  if [[ "$arg" == */* ]]; then
    robot_fleets+=("${arg%%/*}") robots+=("${arg#*/}")
  else
    robot_fleets+=("$fleet") robots+=("$arg")
  fi
done

# Ids as the wire allows them (wire::validate_id): nothing that adds a key chunk or wildcard.
for id in "$fleet" "${robot_fleets[@]}" "${robots[@]}"; do
  [[ "$id" =~ ^[A-Za-z0-9_-]+$ ]] || {
    echo "$0: '$id': ids are [A-Za-z0-9_-]+" >&2
    exit 2
  }
done
if [ "$(printf '%s\n' "${robots[@]}" | sort | uniq -d)" != "" ]; then
  echo "$0: a robot is named twice" >&2
  exit 2
fi
for robot in "${robots[@]}"; do
  # The mapper's and the CA's files share the folder.
  case "$robot" in ca | mapper | router | levelmap-mapper) echo "$0: '$robot' is a reserved name" >&2 && exit 2 ;; esac
done

mkdir -p "$out"
out="$(cd "$out" && pwd)" # router.json5 names its files by absolute path
days="${MAKE_CERTS_DAYS:-825}"
cert_dir="${MAKE_CERTS_DIR:-$out}"
listen="${MAKE_CERTS_LISTEN:-tls/0.0.0.0:7447}"
umask 077 # keys readable by their owner only
work="$(mktemp -d)"
trap 'rm -rf "$work"' EXIT

new_key() { openssl genpkey -algorithm EC -pkeyopt ec_paramgen_curve:P-256 -out "$1" 2>/dev/null; }

if [ ! -f "$out/ca.pem" ] || [ ! -f "$out/ca.key" ]; then
  new_key "$out/ca.key"
  cat >"$work/ca.cnf" <<EOF
[req]
distinguished_name = dn
x509_extensions = ca
prompt = no
[dn]
CN = levelmap $fleet CA
[ca]
basicConstraints = critical, CA:TRUE, pathlen:0
keyUsage = critical, keyCertSign, cRLSign
subjectKeyIdentifier = hash
EOF
  openssl req -x509 -new -key "$out/ca.key" -config "$work/ca.cnf" -days "$days" \
    -sha256 -out "$out/ca.pem"
  echo "made $out/ca.pem"
fi

# sign NAME CN EXTENSIONS: NAME.key (new if missing) and NAME.pem signed by the CA.
sign() {
  local name="$1" cn="$2" extensions="$3"
  [ -f "$out/$name.pem" ] && [ -f "$out/$name.key" ] && return 0
  new_key "$out/$name.key"
  openssl req -new -key "$out/$name.key" -subj "/CN=$cn" -out "$work/$name.csr"
  printf '%s\n' "$extensions" >"$work/$name.ext"
  openssl x509 -req -in "$work/$name.csr" -CA "$out/ca.pem" -CAkey "$out/ca.key" \
    -CAserial "$out/ca.srl" -CAcreateserial -days "$days" -sha256 \
    -extfile "$work/$name.ext" -out "$out/$name.pem" 2>/dev/null
  echo "made $out/$name.pem (CN $cn)"
}

sans="DNS:localhost,IP:127.0.0.1"
IFS=',' read -r -a names <<<"${MAKE_CERTS_MAPPER_NAMES:-}"
for name in "${names[@]}"; do
  name="${name// /}"
  [ -n "$name" ] || continue
  if [[ "$name" =~ ^[0-9.]+$ || "$name" == *:* ]]; then sans+=",IP:$name"; else sans+=",DNS:$name"; fi
done
if [ -f "$out/mapper.pem" ] && [ -n "${MAKE_CERTS_MAPPER_NAMES:-}" ]; then
  echo "$0: keeping the existing $out/mapper.pem; remove it to put MAKE_CERTS_MAPPER_NAMES in a new one" >&2
fi
sign mapper levelmap-mapper "basicConstraints = critical, CA:FALSE
keyUsage = critical, digitalSignature
extendedKeyUsage = serverAuth, clientAuth
subjectAltName = $sans"
for robot in "${robots[@]}"; do
  sign "$robot" "$robot" "basicConstraints = critical, CA:FALSE
keyUsage = critical, digitalSignature
extendedKeyUsage = clientAuth"
done

# The access-control list: per robot, what enters the router from it (ingress) and what the
# router sends it (egress). Zenoh's rules cannot name the certificate's common name in a key,
# so each robot has its own.
rules="" subjects="" policies=""
for k in "${!robots[@]}"; do
  robot="${robots[$k]}" robot_fleet="${robot_fleets[$k]}"
  own="levelmap/$robot_fleet/robots/$robot"
  map="levelmap/$robot_fleet/map/**"
  rules+="
      { id: \"$robot-puts\", permission: \"allow\", flows: [\"ingress\"], messages: [\"put\"],
        key_exprs: [\"$own/node\", \"$own/odom\", \"$own/scan\"] },
      { id: \"$robot-subscribes\", permission: \"allow\", flows: [\"ingress\"],
        messages: [\"declare_subscriber\"],
        key_exprs: [\"$own/ack\", \"$own/localization\", \"$map\"] },
      { id: \"$robot-receives\", permission: \"allow\", flows: [\"egress\"], messages: [\"put\"],
        key_exprs: [\"$own/ack\", \"$own/localization\", \"$map\"] },
      { id: \"$robot-queries\", permission: \"allow\", flows: [\"ingress\"], messages: [\"query\"],
        key_exprs: [\"$map\"] },
      { id: \"$robot-replies\", permission: \"allow\", flows: [\"egress\"], messages: [\"reply\"],
        key_exprs: [\"$map\"] },"
  subjects+="
      { id: \"$robot\", cert_common_names: [\"$robot\"] },"
  policies+="
      { rules: [\"$robot-puts\", \"$robot-subscribes\", \"$robot-receives\", \"$robot-queries\",
                \"$robot-replies\", \"mapper-declarations\"], subjects: [\"$robot\"] },"
done

cat >"$out/router.json5" <<EOF
// The levelmap mapper's Zenoh configuration (fleet "$fleet" and the robots below), written by
// deploy/zenoh/make-certs.sh: mapper.toml's [zenoh] config_file. Robots: $*.
{
  mode: "router",
  listen: { endpoints: ["$listen"] },
  transport: {
    link: {
      tls: {
        root_ca_certificate: "$cert_dir/ca.pem",
        listen_certificate: "$cert_dir/mapper.pem",
        listen_private_key: "$cert_dir/mapper.key",
        // The same certificate when this router connects to another mapper host's.
        connect_certificate: "$cert_dir/mapper.pem",
        connect_private_key: "$cert_dir/mapper.key",
        // Every client must present a certificate signed by ca.pem: its common name is the
        // subject of the access-control list.
        enable_mtls: true,
        close_link_on_expiration: true,
      },
    },
  },
  access_control: {
    enabled: true,
    default_permission: "deny",
    rules: [
      // A robot's publisher asks which subscribers match before it sends: the mapper's
      // subscriptions (levelmap/*/robots/*/{node,odom,scan}) must be declared to it, and its
      // queryable (levelmap/*/map/*) to a robot's querier.
      { id: "mapper-declarations", permission: "allow", flows: ["egress"],
        messages: ["declare_subscriber", "declare_queryable"],
        key_exprs: ["levelmap/*/robots/*/node", "levelmap/*/robots/*/odom", "levelmap/*/robots/*/scan", "levelmap/*/map/**"] },
      // Another mapper host's router (the mapper certificate, which no robot holds): a
      // robot's messages reach its site's owner through whichever router it dialled.
      { id: "mapper-mesh", permission: "allow", flows: ["ingress", "egress"],
        messages: ["put", "delete", "declare_subscriber", "query", "declare_queryable", "reply",
                   "liveliness_token", "declare_liveliness_subscriber", "liveliness_query"],
        key_exprs: ["levelmap/**"] },$rules
    ],
    subjects: [
      { id: "mapper-hosts", cert_common_names: ["levelmap-mapper"] },$subjects
    ],
    policies: [
      { rules: ["mapper-mesh"], subjects: ["mapper-hosts"] },$policies
    ],
  },
}
EOF
echo "wrote $out/router.json5 (robots: $*)"
