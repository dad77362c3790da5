# simreal on Debian 12 / Python 3.11, equivalent to `./run setup` (same Debian packages, the same pinned
# requirements.txt, the same interface-package build). Build: docker build -t simreal .
# Run the demo:  docker run --rm -v $PWD/out:/simreal/out simreal
# Run the tests: docker run --rm simreal ./run test
FROM python:3.11-slim-bookworm

RUN apt-get update && apt-get install -y --no-install-recommends \
      libusb-1.0-0 libegl1 libgl1 libgl1-mesa-dri libglu1-mesa libxrender1 libxcursor1 libxft2 libxinerama1 \
      libfontconfig1 libopengl0 libsm6 libice6 build-essential cmake ninja-build python3-dev python3-venv openfoam \
    && rm -rf /var/lib/apt/lists/*

WORKDIR /simreal
# dependencies first (cached layer): the pinned requirements shared with ./run
COPY requirements.txt ./
RUN python -m venv .venv && .venv/bin/python -m pip install -q --upgrade pip \
    && .venv/bin/python -m pip install -q -r requirements.txt

COPY . .
# ./run setup finds the venv with every requirement installed, installs simreal itself and builds the
# tf2_msgs / simreal_msgs interface packages into it (SIMREAL_PYTHON: the image's python3.11)
ENV SIMREAL_PYTHON=/usr/local/bin/python3.11
RUN ./run setup

CMD ["./run", "demo"]
