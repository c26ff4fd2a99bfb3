#!/usr/bin/env bash
# Installs everything scalefuse needs to build and test on Debian 12 (run as root or with sudo).
set -euo pipefail
SUDO=""
if [ "$(id -u)" -ne 0 ]; then SUDO="sudo"; fi
export DEBIAN_FRONTEND=noninteractive
$SUDO apt-get update -qq
$SUDO apt-get install -y -qq --no-install-recommends \
  build-essential cmake pkg-config \
  libeigen3-dev libcgal-dev libgmp-dev libmpfr-dev libboost-dev \
  libopenvdb-dev libboost-iostreams-dev libboost-system-dev libblosc-dev \
  libtbb-dev liblz4-dev libxxhash-dev libpng-dev libjpeg-dev libsqlite3-dev \
  libcli11-dev nlohmann-json3-dev libtomlplusplus-dev \
  libgtest-dev python3 \
  openmpi-bin libopenmpi-dev slurmctld slurmd slurm-client munge >/dev/null
