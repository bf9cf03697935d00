/*
 * ec_foreign_master — an EtherCAT master written the way a customer writes one against our
 * drives: one C11 file, libc and Linux sockets only. No omnitwin header, no SOEM, nothing
 * shared with the twin: all it knows about the slaves comes from what a third party has, the
 * ESI file (models/ethercat/omnitwin_drive.xml) and the published docs (docs/protocols/
 * ethercat.md, docs/interop-ethercat.md). That is the point of it: a master that shares the
 * twin's code would share its misunderstandings too, and they would go unnoticed. It is the
 * "master we did not write" of issue 14 (tests/CMakeLists.txt builds it as ec_foreign_master).
 *
 * Usage: ec_foreign_master IFACE SECONDS [VELOCITY_COUNTS_PER_S]
 *   IFACE    raw:NAME       EtherCAT frames on an Ethernet interface (AF_PACKET, EtherType
 *                           0x88A4), e.g. the veth end `omnitwin twin` prints;
 *            udp:HOST:PORT  EtherCAT over UDP: each datagram's payload is exactly the
 *                           EtherCAT PDU (2-byte EtherCAT header + datagrams, no Ethernet
 *                           header); the slaves answer the sender. Port 34980 if omitted.
 *   SECONDS  length of the motion phase on CLOCK_MONOTONIC, from the moment all four
 *            drives are in Operation Enabled: a ramp up to VELOCITY (20 % of it), a hold
 *            (50 %), a ramp back down (20 %), standstill at 0 (10 %).
 *   VELOCITY target velocity of every drive in CSV [counts/s], default 65536 (0.5 rev/s).
 *
 * What it does (the steps are marked "Step N" below):
 *   1. counts the slaves (BRD), resets them to INIT, checks each position (APRD), sets station
 *      addresses 0x1001.. (APWR 0x0010), reads each identity from the SII EEPROM; expects 4
 *      omnitwin drives;
 *   2. mailbox SMs (SM0/SM1) → PRE-OP; process-data SMs (SM2 18 bytes out, SM3 24 bytes in,
 *      the ESI's fixed default mapping 0x1600/0x1A00, so no CoE traffic is needed) and two
 *      FMMUs per slave → SAFE-OP; then one frame per 1 ms cycle (LRW of the process image +
 *      an AL status read of every slave); after 10 good cycles → OP;
 *   3. CiA 402: modes of operation 9 (CSV, in the RxPDO), controlword 6 → 7 → 15 until every
 *      drive is in Operation Enabled, then the velocity profile;
 *   4. every cycle: the WKC of every datagram (LRW 12 = 4 slaves × (1 read + 2 write), each
 *      FPRD 1), lost frames, AL state; at the end controlword 6 then 0, AL INIT, one summary
 *      line on stdout, exit 0. Failures: a message on stderr, AL INIT, exit 1 (2: usage).
 *   5. SIGINT/SIGTERM: the velocity ramps to 0 quickly, the drives and slaves are brought
 *      down as above, the summary is printed, exit 0.
 * Diagnostics go to stderr; stdout carries only the summary line.
 */
#define _GNU_SOURCE
#include <arpa/inet.h>
#include <errno.h>
#include <linux/if_packet.h>
#include <net/ethernet.h>
#include <net/if.h>
#include <netdb.h>
#include <poll.h>
#include <sched.h>
#include <signal.h>
#include <stdarg.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/ioctl.h>
#include <sys/mman.h>
#include <sys/socket.h>
#include <time.h>
#include <unistd.h>

/* ---- what the ESI and the docs say about the slaves ---------------------------------------- */
#define EXPECTED_SLAVES 4
#define VENDOR_ID 0x00000F1Cu     /* omnitwin test vendor (not ETG-assigned) */
#define PRODUCT_CODE 0x00000402u  /* omnitwin drive 1-axis */
#define FIRST_STATION 0x1001
#define SM_MBX_OUT 0x1000         /* SM0: 128 bytes, control 0x26 (mailbox, master writes) */
#define SM_MBX_IN 0x1080          /* SM1: 128 bytes, control 0x22 (mailbox, master reads) */
#define MBX_SIZE 128
#define SM_OUTPUTS 0x1100         /* SM2: RxPDO 0x1600, control 0x64 (buffered, write, watchdog) */
#define SM_INPUTS 0x1180          /* SM3: TxPDO 0x1A00, control 0x20 (buffered, read) */
#define RX_BYTES 18               /* 0x6040 u16, 0x607A i32, 0x60FF i32, 0x6071 i16, 0x6060 i8, pad, 0x60B1 i32 */
#define TX_BYTES 24               /* 0x6041 u16, 0x6064 i32, 0x606C i32, 0x6077 i16, 0x6061 i8, pad, 0x60FD, 0x60F4, 0x603F */
#define RX_CONTROLWORD 0
#define RX_TARGET_VELOCITY 6
#define RX_MODE 12
#define TX_STATUSWORD 0
#define TX_VELOCITY_ACTUAL 6
#define TX_MODE_DISPLAY 12
#define TX_ERROR_CODE 22
#define MODE_CSV 9

/* ---- ESC registers (EtherCAT standard) ----------------------------------------------------- */
#define REG_TYPE 0x0000
#define REG_STATION 0x0010
#define REG_AL_CONTROL 0x0120
#define REG_AL_STATUS 0x0130      /* read 6 bytes: status u16, reserved, status code u16 at 0x0134 */
#define REG_EEPROM_CONFIG 0x0500
#define REG_EEPROM_CONTROL 0x0502 /* control/status u16, then the word address u32 at 0x0504 */
#define REG_EEPROM_DATA 0x0508
#define REG_FMMU0 0x0600
#define REG_SM0 0x0800
#define REG_DC_ACTIVATION 0x0981
#define AL_INIT 1
#define AL_PREOP 2
#define AL_SAFEOP 4
#define AL_OP 8
#define AL_ERROR 0x10
#define AL_ACK 0x10

/* ---- datagram commands ---- */
enum { APRD = 1, APWR = 2, FPRD = 4, FPWR = 5, BRD = 7, BWR = 8, LRW = 12 };

/* ---- our choices ---- */
#define CYCLE_NS 1000000L             /* 1 ms */
#define REPLY_WINDOW_NS 900000L       /* a cyclic frame not back 0.9 ms after it was sent is lost */
#define ACYCLIC_TIMEOUT_NS 20000000L  /* 20 ms per try, 3 tries */
#define LOGICAL_BASE 0x00000000u      /* image: outputs of slaves 1..4, then their inputs */
#define IMAGE_BYTES (EXPECTED_SLAVES * (RX_BYTES + TX_BYTES))
#define EXPECTED_LRW_WKC (EXPECTED_SLAVES * 3)
#define SAFEOP_WARMUP_CYCLES 10       /* process data in SAFE-OP before asking for OP */
#define STATE_TIMEOUT_S 3.0           /* each AL or CiA 402 step must finish within this */
#define MAX_CONSECUTIVE_BAD 20        /* lost or wrong-WKC cycles in a row (SM watchdog: 100 ms) */
#define MAX_BAD_FRACTION 0.01         /* of all cycles, checked at the end */
#define TRACKING_TOLERANCE 0.05       /* velocity actual vs command at the end of the hold */
#define DEFAULT_VELOCITY 65536

/* ---- little helpers ------------------------------------------------------------------------ */
static void put16(uint8_t *p, uint16_t v) { p[0] = (uint8_t)v; p[1] = (uint8_t)(v >> 8); }
static void put32(uint8_t *p, uint32_t v) { for (int i = 0; i < 4; ++i) p[i] = (uint8_t)(v >> (8 * i)); }
static uint16_t get16(const uint8_t *p) { return (uint16_t)(p[0] | (p[1] << 8)); }
static uint32_t get32(const uint8_t *p) {
  return (uint32_t)p[0] | ((uint32_t)p[1] << 8) | ((uint32_t)p[2] << 16) | ((uint32_t)p[3] << 24);
}
static int64_t now_ns(void) {
  struct timespec ts;
  clock_gettime(CLOCK_MONOTONIC, &ts);
  return (int64_t)ts.tv_sec * 1000000000 + ts.tv_nsec;
}
static struct timespec to_ts(int64_t ns) {
  struct timespec ts = {(time_t)(ns / 1000000000), (long)(ns % 1000000000)};
  return ts;
}
static void sleep_ns(int64_t ns) {
  struct timespec ts = to_ts(ns);
  (void)clock_nanosleep(CLOCK_MONOTONIC, 0, &ts, NULL);
}

static volatile sig_atomic_t g_signal = 0;  /* the signal that asked us to stop (0: none) */
static void on_signal(int sig) { g_signal = sig; }

static int64_t g_start_ns;  /* program start, for "OP after" */
static struct {             /* counters for the summary */
  long cycles, lost, wkc_errors, stale, overruns, consecutive_bad;
  int64_t max_round_trip_ns;  /* cyclic frames that came back in time */
} g_stats;

/* ---- the link: raw Ethernet or UDP --------------------------------------------------------- */
struct link {
  int fd;
  int raw;                       /* 1: AF_PACKET on an interface, 0: UDP */
  int ifindex;
  uint8_t mac[6];
  struct sockaddr_storage peer;  /* UDP: the slaves' HOST:PORT */
  socklen_t peer_len;
};
static struct link g_link = {.fd = -1};
static const char *g_iface = "";

#define RECV_IGNORED (-2)  /* something arrived that is not an EtherCAT reply for us */

static int link_open(struct link *l, const char *spec, char *err, size_t errlen) {
  memset(l, 0, sizeof *l);
  l->fd = -1;
  if (strncmp(spec, "raw:", 4) == 0) {
    const char *name = spec + 4;
    struct ifreq ifr;
    if (strlen(name) == 0 || strlen(name) >= sizeof ifr.ifr_name) {
      snprintf(err, errlen, "bad interface name in '%s'", spec);
      return -1;
    }
    l->raw = 1;
    l->fd = socket(AF_PACKET, SOCK_RAW | SOCK_CLOEXEC, htons(0x88A4));
    if (l->fd < 0) {
      snprintf(err, errlen, "%s: AF_PACKET socket: %s (needs root or CAP_NET_RAW)", spec, strerror(errno));
      return -1;
    }
    memset(&ifr, 0, sizeof ifr);
    strncpy(ifr.ifr_name, name, sizeof ifr.ifr_name - 1);
    if (ioctl(l->fd, SIOCGIFINDEX, &ifr) < 0) {
      snprintf(err, errlen, "%s: no such interface: %s", spec, strerror(errno));
      return -1;
    }
    l->ifindex = ifr.ifr_ifindex;
    if (ioctl(l->fd, SIOCGIFHWADDR, &ifr) < 0) {
      snprintf(err, errlen, "%s: cannot read its MAC address: %s", spec, strerror(errno));
      return -1;
    }
    memcpy(l->mac, ifr.ifr_hwaddr.sa_data, 6);
    struct sockaddr_ll sll;
    memset(&sll, 0, sizeof sll);
    sll.sll_family = AF_PACKET;
    sll.sll_protocol = htons(0x88A4);
    sll.sll_ifindex = l->ifindex;
    if (bind(l->fd, (struct sockaddr *)&sll, sizeof sll) < 0) {
      snprintf(err, errlen, "%s: bind: %s", spec, strerror(errno));
      return -1;
    }
#ifdef PACKET_IGNORE_OUTGOING
    int one = 1;  /* best effort: link_recv() also drops our own outgoing frames */
    (void)setsockopt(l->fd, SOL_PACKET, PACKET_IGNORE_OUTGOING, &one, sizeof one);
#endif
    return 0;
  }
  if (strncmp(spec, "udp:", 4) == 0) {
    char host[256], port[16] = "34980";
    const char *h = spec + 4, *colon;
    if (*h == '[') {  /* udp:[IPv6]:PORT */
      const char *close = strchr(h, ']');
      if (!close || (size_t)(close - h - 1) >= sizeof host) {
        snprintf(err, errlen, "bad IPv6 host in '%s'", spec);
        return -1;
      }
      memcpy(host, h + 1, (size_t)(close - h - 1));
      host[close - h - 1] = '\0';
      colon = close[1] == ':' ? close + 1 : NULL;
    } else {
      colon = strrchr(h, ':');
      size_t n = colon ? (size_t)(colon - h) : strlen(h);
      if (n == 0 || n >= sizeof host) {
        snprintf(err, errlen, "bad host in '%s'", spec);
        return -1;
      }
      memcpy(host, h, n);
      host[n] = '\0';
    }
    if (colon) snprintf(port, sizeof port, "%s", colon + 1);
    struct addrinfo hints, *res = NULL;
    memset(&hints, 0, sizeof hints);
    hints.ai_family = AF_UNSPEC;
    hints.ai_socktype = SOCK_DGRAM;
    int rc = getaddrinfo(host, port, &hints, &res);
    if (rc != 0 || !res) {
      snprintf(err, errlen, "%s: cannot resolve: %s", spec, gai_strerror(rc));
      return -1;
    }
    memcpy(&l->peer, res->ai_addr, res->ai_addrlen);
    l->peer_len = res->ai_addrlen;
    l->fd = socket(res->ai_family, SOCK_DGRAM | SOCK_CLOEXEC, 0);
    freeaddrinfo(res);
    if (l->fd < 0) {
      snprintf(err, errlen, "%s: UDP socket: %s", spec, strerror(errno));
      return -1;
    }
    return 0;  /* the first sendto() binds an ephemeral port; the slaves answer it */
  }
  snprintf(err, errlen, "'%s': expected raw:IFNAME or udp:HOST:PORT", spec);
  return -1;
}

/* One PDU (EtherCAT header + datagrams) to the segment. 0 on success. */
static int link_send(struct link *l, const uint8_t *pdu, size_t len) {
  ssize_t n;
  if (!l->raw) {
    do n = sendto(l->fd, pdu, len, 0, (struct sockaddr *)&l->peer, l->peer_len);
    while (n < 0 && errno == EINTR);
    return n == (ssize_t)len ? 0 : -1;
  }
  uint8_t frame[1514];
  memset(frame, 0xFF, 6);           /* destination: broadcast */
  memcpy(frame + 6, l->mac, 6);     /* source: our MAC */
  frame[12] = 0x88;                 /* EtherType 0x88A4 */
  frame[13] = 0xA4;
  memcpy(frame + 14, pdu, len);
  size_t total = 14 + len;
  if (total < 60) {                 /* Ethernet minimum frame (without FCS) */
    memset(frame + total, 0, 60 - total);
    total = 60;
  }
  do n = send(l->fd, frame, total, 0);
  while (n < 0 && errno == EINTR);
  return n == (ssize_t)total ? 0 : -1;
}

/* Waits up to timeout_ns for one frame: its PDU length in pdu, 0 on timeout, RECV_IGNORED for
 * something that is not an EtherCAT PDU coming back to us, -1 on a socket error. */
static int link_recv(struct link *l, uint8_t *pdu, size_t cap, int64_t timeout_ns) {
  struct pollfd p = {.fd = l->fd, .events = POLLIN};
  struct timespec ts = to_ts(timeout_ns < 0 ? 0 : timeout_ns);
  int r = ppoll(&p, 1, &ts, NULL);
  if (r < 0) return errno == EINTR ? RECV_IGNORED : -1;
  if (r == 0) return 0;
  uint8_t buf[1600];
  ssize_t n;
  const uint8_t *body = buf;
  if (l->raw) {
    struct sockaddr_ll from;
    socklen_t fl = sizeof from;
    n = recvfrom(l->fd, buf, sizeof buf, MSG_DONTWAIT, (struct sockaddr *)&from, &fl);
    if (n < 0) return (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR) ? RECV_IGNORED : -1;
    if (from.sll_pkttype == PACKET_OUTGOING) return RECV_IGNORED;  /* our own frame going out */
    if (n < 14 + 2 || buf[12] != 0x88 || buf[13] != 0xA4) return RECV_IGNORED;
    body = buf + 14;
    n -= 14;
  } else {
    n = recv(l->fd, buf, sizeof buf, MSG_DONTWAIT);
    if (n < 0) {  /* ECONNREFUSED: ICMP for an earlier datagram (nobody listened yet) */
      if (errno == EAGAIN || errno == EWOULDBLOCK || errno == EINTR || errno == ECONNREFUSED) return RECV_IGNORED;
      return -1;
    }
  }
  if (n < 2) return RECV_IGNORED;
  uint16_t hdr = get16(body);
  size_t len = 2 + (hdr & 0x07FFu);        /* EtherCAT header: length 11 bits, type 4 bits */
  if ((hdr >> 12) != 1 || len > (size_t)n || len > cap) return RECV_IGNORED;  /* Ethernet padding is cut */
  memcpy(pdu, body, len);
  return (int)len;
}

/* ---- frames of datagrams ------------------------------------------------------------------- */
#define MAX_DATAGRAMS 12
struct frame {
  uint8_t buf[1500];
  size_t len;                 /* PDU length: 2-byte EtherCAT header + datagrams */
  int n;
  size_t off[MAX_DATAGRAMS];  /* offset of each datagram's header */
};
static uint8_t g_index;       /* datagram index of the frame in flight */

static void frame_init(struct frame *f) { f->len = 2; f->n = 0; }

/* Appends a datagram (data NULL: zeros); returns its number in the frame. */
static int frame_add(struct frame *f, uint8_t cmd, uint16_t adp, uint16_t ado, const void *data, uint16_t len) {
  if (f->n > 0) {  /* the previous datagram gets the "more follows" bit */
    uint8_t *prev = f->buf + f->off[f->n - 1];
    put16(prev + 6, (uint16_t)(get16(prev + 6) | 0x8000));
  }
  uint8_t *d = f->buf + f->len;
  d[0] = cmd;
  d[1] = 0;  /* index: set when sent */
  put16(d + 2, adp);
  put16(d + 4, ado);
  put16(d + 6, (uint16_t)(len & 0x07FF));
  put16(d + 8, 0);  /* IRQ */
  if (data) memcpy(d + 10, data, len); else memset(d + 10, 0, len);
  put16(d + 10 + len, 0);  /* working counter */
  f->off[f->n] = f->len;
  f->len += 10 + (size_t)len + 2;
  put16(f->buf, (uint16_t)((f->len - 2) | 0x1000));  /* type 1: EtherCAT commands */
  return f->n++;
}
static uint8_t *dg_data(struct frame *f, int i) { return f->buf + f->off[i] + 10; }
static uint16_t dg_wkc(const struct frame *f, int i) {
  const uint8_t *d = f->buf + f->off[i];
  return get16(d + 10 + (get16(d + 6) & 0x07FF));
}

/* Sends the frame and waits until `deadline_ns` for it to come back (same length, index and
 * commands); the reply replaces the frame's contents. 1: back, 0: lost, -1: link error. */
static int exchange(struct frame *f, int64_t deadline_ns) {
  ++g_index;
  for (int i = 0; i < f->n; ++i) f->buf[f->off[i] + 1] = g_index;
  if (link_send(&g_link, f->buf, f->len) != 0) return -1;
  uint8_t rx[1500];
  for (;;) {
    int64_t left = deadline_ns - now_ns();
    int n = link_recv(&g_link, rx, sizeof rx, left > 0 ? left : 0);
    if (n < 0 && n != RECV_IGNORED) return -1;
    if (n == 0) return 0;  /* nothing more within the deadline */
    if (n == RECV_IGNORED) continue;
    int ours = (size_t)n == f->len;
    for (int i = 0; ours && i < f->n; ++i)
      ours = rx[f->off[i]] == f->buf[f->off[i]] && rx[f->off[i] + 1] == g_index;
    if (!ours) {  /* a late reply to an earlier frame, or someone else's */
      ++g_stats.stale;
      continue;
    }
    memcpy(f->buf, rx, (size_t)n);
    return 1;
  }
}

/* One datagram outside the cycle, up to 3 tries. Returns its WKC, -1 when nothing came back. */
static int xfer(uint8_t cmd, uint16_t adp, uint16_t ado, void *data, uint16_t len) {
  for (int attempt = 0; attempt < 3; ++attempt) {
    struct frame f;
    frame_init(&f);
    frame_add(&f, cmd, adp, ado, data, len);
    int r = exchange(&f, now_ns() + ACYCLIC_TIMEOUT_NS);
    if (r < 0) return -1;
    if (r == 1) {
      if (data) memcpy(data, dg_data(&f, 0), len);
      return dg_wkc(&f, 0);
    }
  }
  return -1;
}
static uint16_t station(int i) { return (uint16_t)(FIRST_STATION + i); }

/* ---- failing cleanly ----------------------------------------------------------------------- */
static const char *al_code_text(uint16_t c) {
  switch (c) {
    case 0x0000: return "no error";
    case 0x0011: return "invalid requested state change";
    case 0x0012: return "unknown requested state";
    case 0x0013: return "bootstrap not supported";
    case 0x0016: return "invalid mailbox configuration";
    case 0x0017: return "invalid sync manager configuration";
    case 0x001B: return "sync manager watchdog";
    case 0x001D: return "invalid output configuration";
    case 0x001E: return "invalid input configuration";
    case 0x0030: return "invalid DC sync configuration";
    default: return "see the ETG AL status code list";
  }
}
static const char *al_state_text(uint16_t s) {
  switch (s & 0x0F) {
    case AL_INIT: return "INIT";
    case AL_PREOP: return "PRE-OP";
    case 3: return "BOOT";
    case AL_SAFEOP: return "SAFE-OP";
    case AL_OP: return "OP";
    default: return "?";
  }
}

/* Every slave to INIT (acknowledging errors): the drives disable when outputs stop. */
static void all_to_init(void) {
  uint8_t ctl[2];
  put16(ctl, AL_INIT | AL_ACK);
  (void)xfer(BWR, 0, REG_AL_CONTROL, ctl, 2);
}

static void fail(const char *fmt, ...) __attribute__((noreturn, format(printf, 1, 2)));
static void fail(const char *fmt, ...) {
  va_list ap;
  va_start(ap, fmt);
  fprintf(stderr, "foreign-master: FAILED on %s: ", g_iface);
  vfprintf(stderr, fmt, ap);
  va_end(ap);
  fprintf(stderr, " (%ld cycles, %ld lost, %ld wkc errors)\n", g_stats.cycles, g_stats.lost, g_stats.wkc_errors);
  if (g_link.fd >= 0) all_to_init();
  exit(1);
}

/* ---- Steps 1 and 2: finding the slaves, the AL state walk ---------------------------------- */

/* Reads AL status and status code of slave i (FPRD 0x0130, 6 bytes). 0 on success. */
static int read_al(int i, uint16_t *status, uint16_t *code) {
  uint8_t b[6] = {0};
  if (xfer(FPRD, station(i), REG_AL_STATUS, b, 6) != 1) return -1;
  *status = get16(b);
  *code = get16(b + 4);
  return 0;
}

/* Asks every slave for `state` and waits until all are there; a refusal fails with its code. */
static void request_state(uint16_t state) {
  uint8_t ctl[2];
  put16(ctl, state);
  for (int i = 0; i < EXPECTED_SLAVES; ++i)
    if (xfer(FPWR, station(i), REG_AL_CONTROL, ctl, 2) != 1)
      fail("slave %d (station 0x%04X) did not take the AL control write for %s", i + 1, station(i), al_state_text(state));
  int64_t until = now_ns() + (int64_t)(STATE_TIMEOUT_S * 1e9);
  for (int i = 0; i < EXPECTED_SLAVES;) {
    uint16_t st = 0, code = 0;
    if (read_al(i, &st, &code) != 0) fail("slave %d does not answer AL status reads", i + 1);
    if (st & AL_ERROR)
      fail("slave %d refused %s: AL status 0x%04X (%s + error), AL status code 0x%04X (%s)", i + 1,
           al_state_text(state), st, al_state_text(st), code, al_code_text(code));
    if ((st & 0x0F) == state) { ++i; continue; }
    if (now_ns() > until)
      fail("slave %d still in %s %.1f s after asking for %s", i + 1, al_state_text(st), STATE_TIMEOUT_S, al_state_text(state));
    if (g_signal) return;
    sleep_ns(1000000);
  }
  fprintf(stderr, "foreign-master: all %d slaves in %s\n", EXPECTED_SLAVES, al_state_text(state));
}

/* One 8-byte SII read (words addr, addr+1, addr+2, addr+3) over the EEPROM registers. */
static int sii_read(int i, uint16_t word, uint8_t out[8]) {
  uint8_t cmd[6];
  put16(cmd, 0x0100);  /* read command */
  put32(cmd + 2, word);
  if (xfer(FPWR, station(i), REG_EEPROM_CONTROL, cmd, 6) != 1) return -1;
  for (int tries = 0;; ++tries) {
    uint8_t st[2];
    if (xfer(FPRD, station(i), REG_EEPROM_CONTROL, st, 2) != 1) return -1;
    uint16_t s = get16(st);
    if (s & 0x6800) return -1;           /* NACK, write-enable or checksum error */
    if (!(s & 0x8000)) break;            /* not busy: data ready */
    if (tries == 100) return -1;
    sleep_ns(100000);
  }
  memset(out, 0, 8);
  return xfer(FPRD, station(i), REG_EEPROM_DATA, out, 8) == 1 ? 0 : -1;
}

static void write_sm(int i, int sm, uint16_t start, uint16_t len, uint8_t control) {
  uint8_t r[8] = {0};
  put16(r, start);
  put16(r + 2, len);
  r[4] = control;
  r[6] = 0x01;  /* activate */
  if (xfer(FPWR, station(i), (uint16_t)(REG_SM0 + 8 * sm), r, 8) != 1)
    fail("slave %d: SM%d configuration write not taken", i + 1, sm);
}
static void write_fmmu(int i, int fmmu, uint32_t logical, uint16_t len, uint16_t physical, uint8_t type) {
  uint8_t r[16] = {0};
  put32(r, logical);
  put16(r + 4, len);
  r[6] = 0;     /* logical start bit */
  r[7] = 7;     /* logical end bit */
  put16(r + 8, physical);
  r[10] = 0;    /* physical start bit */
  r[11] = type; /* 1 read (inputs), 2 write (outputs) */
  r[12] = 0x01; /* activate */
  if (xfer(FPWR, station(i), (uint16_t)(REG_FMMU0 + 16 * fmmu), r, 16) != 1)
    fail("slave %d: FMMU%d configuration write not taken", i + 1, fmmu);
}

static void start_up(void) {
  /* Step 1a: count the slaves. The segment may still be coming up: try for 2 s. */
  int wkc = -1;
  for (int64_t until = now_ns() + 2000000000LL; wkc < 0 && now_ns() < until && !g_signal;) {
    uint8_t type[2] = {0};
    wkc = xfer(BRD, 0, REG_TYPE, type, 2);
  }
  if (g_signal) return;
  if (wkc < 0) fail("no EtherCAT frame came back within 2 s: no slaves there");
  if (wkc != EXPECTED_SLAVES) fail("%d slaves answered a broadcast read, expected %d", wkc, EXPECTED_SLAVES);

  /* Step 1b: back to a known state: INIT (acknowledging any error), no FMMUs, no SMs, no SYNC. */
  uint8_t zeros[256] = {0}, ctl[2];
  put16(ctl, AL_INIT | AL_ACK);
  if (xfer(BWR, 0, REG_AL_CONTROL, ctl, 2) != EXPECTED_SLAVES) fail("not every slave took the INIT request");
  if (xfer(BWR, 0, REG_FMMU0, zeros, 256) != EXPECTED_SLAVES) fail("not every slave took the FMMU reset");
  if (xfer(BWR, 0, REG_SM0, zeros, 128) != EXPECTED_SLAVES) fail("not every slave took the SM reset");
  if (xfer(BWR, 0, REG_DC_ACTIVATION, zeros, 1) != EXPECTED_SLAVES) fail("not every slave took the SYNC reset");
  /* No station addresses yet: a broadcast read ORs every slave's AL status; 0x0001 = all INIT. */
  for (int64_t until = now_ns() + (int64_t)(STATE_TIMEOUT_S * 1e9);;) {
    uint8_t st[2] = {0};
    if (xfer(BRD, 0, REG_AL_STATUS, st, 2) != EXPECTED_SLAVES) fail("not every slave answers AL status reads");
    if (get16(st) == AL_INIT) break;
    if (now_ns() > until) fail("the slaves are not all in INIT (AL status ORed 0x%04X)", get16(st));
    sleep_ns(1000000);
  }

  /* Step 1c: each position answers (APRD: ADP = -position), gets its station address (APWR
   * 0x0010) and answers at it (FPRD); then its identity from the SII. */
  for (int i = 0; i < EXPECTED_SLAVES; ++i) {
    uint8_t a[2] = {0};
    if (xfer(APRD, (uint16_t)(0 - i), REG_TYPE, a, 2) != 1) fail("no slave answers at position %d", i);
    put16(a, station(i));
    if (xfer(APWR, (uint16_t)(0 - i), REG_STATION, a, 2) != 1) fail("slave at position %d: station address not set", i);
  }
  for (int i = 0; i < EXPECTED_SLAVES; ++i) {
    uint8_t a[2] = {0}, id[8], own[2] = {0, 0};
    if (xfer(FPRD, station(i), REG_STATION, a, 2) != 1 || get16(a) != station(i))
      fail("slave %d does not answer at station 0x%04X", i + 1, station(i));
    (void)xfer(FPWR, station(i), REG_EEPROM_CONFIG, own, 2);  /* EEPROM to the master side */
    if (sii_read(i, 0x0008, id) != 0) fail("slave %d: SII EEPROM read failed", i + 1);
    uint32_t vendor = get32(id), product = get32(id + 4);
    fprintf(stderr, "foreign-master: slave %d station 0x%04X vendor 0x%08X product 0x%08X\n", i + 1, station(i),
            vendor, product);
    if (vendor != VENDOR_ID || product != PRODUCT_CODE)
      fail("slave %d is vendor 0x%08X product 0x%08X, expected 0x%08X/0x%08X (omnitwin drive 1-axis)", i + 1,
           vendor, product, VENDOR_ID, PRODUCT_CODE);
  }
  if (g_signal) return;

  /* Step 2a: mailbox SMs as the ESI says, then PRE-OP (the slaves check them: else 0x0016). */
  for (int i = 0; i < EXPECTED_SLAVES; ++i) {
    write_sm(i, 0, SM_MBX_OUT, MBX_SIZE, 0x26);
    write_sm(i, 1, SM_MBX_IN, MBX_SIZE, 0x22);
  }
  request_state(AL_PREOP);
  if (g_signal) return;

  /* Step 2b: process data. The ESI's default assignment (0x1C12 = 0x1600, 0x1C13 = 0x1A00)
   * is what we use, so no SDO is needed. Image: outputs of slave i at 18·i, inputs at
   * 72 + 24·i. The slaves check the SM lengths against the assigned PDOs (0x001D/0x001E). */
  for (int i = 0; i < EXPECTED_SLAVES; ++i) {
    write_sm(i, 2, SM_OUTPUTS, RX_BYTES, 0x64);
    write_sm(i, 3, SM_INPUTS, TX_BYTES, 0x20);
    write_fmmu(i, 0, LOGICAL_BASE + (uint32_t)(RX_BYTES * i), RX_BYTES, SM_OUTPUTS, 2);
    write_fmmu(i, 1, LOGICAL_BASE + (uint32_t)(EXPECTED_SLAVES * RX_BYTES + TX_BYTES * i), TX_BYTES, SM_INPUTS, 1);
  }
  request_state(AL_SAFEOP);
}

/* ---- Steps 2c–4: the cycle ----------------------------------------------------------------- */
static uint8_t g_image[IMAGE_BYTES];
static uint8_t *outputs_of(int i) { return g_image + RX_BYTES * i; }
static const uint8_t *inputs_of(int i) { return g_image + EXPECTED_SLAVES * RX_BYTES + TX_BYTES * i; }
static uint16_t g_al[EXPECTED_SLAVES], g_al_code[EXPECTED_SLAVES];

/* One cycle's frame: LRW of the image, the AL status of every slave and, when al_request is
 * not 0, an AL control write to every slave. Returns 1 when it came back with every WKC
 * right, 0 when a WKC was wrong, -1 when it did not come back in time (lost). */
static int cycle_frame(uint16_t al_request) {
  struct frame f;
  frame_init(&f);
  int lrw = frame_add(&f, LRW, (uint16_t)(LOGICAL_BASE & 0xFFFF), (uint16_t)(LOGICAL_BASE >> 16), g_image, IMAGE_BYTES);
  int st0 = -1, ctl0 = -1;
  if (al_request) {
    uint8_t ctl[2];
    put16(ctl, al_request);
    for (int i = 0; i < EXPECTED_SLAVES; ++i) {
      int k = frame_add(&f, FPWR, station(i), REG_AL_CONTROL, ctl, 2);
      if (i == 0) ctl0 = k;
    }
  }
  for (int i = 0; i < EXPECTED_SLAVES; ++i) {
    int k = frame_add(&f, FPRD, station(i), REG_AL_STATUS, NULL, 6);
    if (i == 0) st0 = k;
  }
  ++g_stats.cycles;
  int64_t sent = now_ns();
  int r = exchange(&f, sent + REPLY_WINDOW_NS);
  if (r < 0) fail("link error: %s", strerror(errno));
  if (r == 0) {
    ++g_stats.lost;
    ++g_stats.consecutive_bad;
    if (g_stats.lost <= 5)
      fprintf(stderr, "foreign-master: cycle %ld: frame not back %.1f ms after it was sent (lost)\n",
              g_stats.cycles, REPLY_WINDOW_NS / 1e6);
    return -1;
  }
  if (now_ns() - sent > g_stats.max_round_trip_ns) g_stats.max_round_trip_ns = now_ns() - sent;
  int ok = dg_wkc(&f, lrw) == EXPECTED_LRW_WKC;
  for (int i = 0; i < EXPECTED_SLAVES; ++i) {
    if (dg_wkc(&f, st0 + i) == 1) {
      g_al[i] = get16(dg_data(&f, st0 + i));
      g_al_code[i] = get16(dg_data(&f, st0 + i) + 4);
    } else {
      ok = 0;
    }
    if (ctl0 >= 0 && dg_wkc(&f, ctl0 + i) != 1) ok = 0;
  }
  /* The inputs half of the returned image; our outputs stay as we wrote them. */
  if (dg_wkc(&f, lrw) != 0)
    memcpy(g_image + EXPECTED_SLAVES * RX_BYTES, dg_data(&f, lrw) + EXPECTED_SLAVES * RX_BYTES,
           EXPECTED_SLAVES * TX_BYTES);
  if (!ok) {
    ++g_stats.wkc_errors;
    ++g_stats.consecutive_bad;
    if (g_stats.wkc_errors <= 5)
      fprintf(stderr, "foreign-master: cycle %ld: WKC %u (expected %d)\n", g_stats.cycles, dg_wkc(&f, lrw),
              EXPECTED_LRW_WKC);
    return 0;
  }
  g_stats.consecutive_bad = 0;
  return 1;
}

/* CiA 402 statusword → state (facts: bits 0-3, 5, 6). */
enum drive_state { DS_NOT_READY, DS_SWITCH_ON_DISABLED, DS_READY, DS_SWITCHED_ON, DS_ENABLED, DS_QUICK_STOP, DS_FAULT };
static enum drive_state drive_state(uint16_t sw) {
  if ((sw & 0x4F) == 0x40) return DS_SWITCH_ON_DISABLED;
  if ((sw & 0x6F) == 0x21) return DS_READY;
  if ((sw & 0x6F) == 0x23) return DS_SWITCHED_ON;
  if ((sw & 0x6F) == 0x27) return DS_ENABLED;
  if ((sw & 0x6F) == 0x07) return DS_QUICK_STOP;
  if ((sw & 0x4F) == 0x08 || (sw & 0x4F) == 0x0F) return DS_FAULT;
  return DS_NOT_READY;
}
/* The controlword that moves a drive one step towards Operation Enabled. */
static uint16_t controlword_towards_enabled(enum drive_state s, uint16_t previous) {
  switch (s) {
    case DS_FAULT: return previous == 0x0080 ? 0x0000 : 0x0080;  /* fault reset on the rising edge */
    case DS_SWITCH_ON_DISABLED: return 0x0006;                      /* shutdown */
    case DS_READY: return 0x0007;                                   /* switch on */
    case DS_SWITCHED_ON: case DS_ENABLED: return 0x000F;            /* enable operation */
    case DS_QUICK_STOP: return 0x0000;                              /* disable voltage */
    default: return 0x0000;
  }
}

static uint16_t statusword(int i) { return get16(inputs_of(i) + TX_STATUSWORD); }
static int32_t velocity_actual(int i) { return (int32_t)get32(inputs_of(i) + TX_VELOCITY_ACTUAL); }
static void set_outputs(int i, uint16_t cw, int32_t velocity) {
  put16(outputs_of(i) + RX_CONTROLWORD, cw);
  put32(outputs_of(i) + RX_TARGET_VELOCITY, (uint32_t)velocity);
  outputs_of(i)[RX_MODE] = MODE_CSV;
}

/* "[a, b, c, d]" for the summary, or "[not reached]". */
static const char *four_values(char *buf, size_t n, const int32_t v[EXPECTED_SLAVES], int valid) {
  if (valid) snprintf(buf, n, "[%d, %d, %d, %d]", v[0], v[1], v[2], v[3]);
  else snprintf(buf, n, "[not reached]");
  return buf;
}

enum phase { PH_SAFEOP, PH_WAIT_OP, PH_ENABLE, PH_RUN, PH_SHUTDOWN, PH_DISABLE, PH_DONE };

int main(int argc, char **argv) {
  if (argc < 3 || argc > 4) {
    fprintf(stderr, "usage: %s IFACE SECONDS [VELOCITY_COUNTS_PER_S]\n"
                    "  IFACE: raw:IFNAME (AF_PACKET) or udp:HOST:PORT (EtherCAT over UDP)\n", argv[0]);
    return 2;
  }
  g_iface = argv[1];
  char *end = NULL;
  double seconds = strtod(argv[2], &end);
  if (!end || *end || !(seconds > 0) || seconds > 86400) {
    fprintf(stderr, "foreign-master: SECONDS must be a positive number, got '%s'\n", argv[2]);
    return 2;
  }
  long velocity = DEFAULT_VELOCITY;
  if (argc == 4) {
    velocity = strtol(argv[3], &end, 10);
    if (!end || *end || velocity < -2000000 || velocity > 2000000) {
      fprintf(stderr, "foreign-master: VELOCITY must be an integer in ±2000000 counts/s, got '%s'\n", argv[3]);
      return 2;
    }
  }
  struct sigaction sa;
  memset(&sa, 0, sizeof sa);
  sa.sa_handler = on_signal;  /* no SA_RESTART: sleeps and polls return early */
  sigaction(SIGINT, &sa, NULL);
  sigaction(SIGTERM, &sa, NULL);
  /* Best effort, as a real-time master would: lock memory, run above normal tasks. */
  (void)mlockall(MCL_CURRENT | MCL_FUTURE);
  struct sched_param sp = {.sched_priority = 20};
  if (sched_setscheduler(0, SCHED_FIFO, &sp) != 0)
    fprintf(stderr, "foreign-master: no real-time priority (%s): running as a normal task\n", strerror(errno));

  char err[256];
  if (link_open(&g_link, g_iface, err, sizeof err) != 0) {
    fprintf(stderr, "foreign-master: %s\n", err);
    return 1;
  }
  g_start_ns = now_ns();

  start_up();  /* Steps 1, 2a, 2b: the slaves in SAFE-OP */
  if (g_signal) {
    all_to_init();
    fprintf(stderr, "foreign-master: stopped by signal %d before OP\n", (int)g_signal);
    return 0;
  }

  /* Steps 2c, 3, 4: one frame per 1 ms cycle from here on. */
  for (int i = 0; i < EXPECTED_SLAVES; ++i) set_outputs(i, 0, 0);
  enum phase phase = PH_SAFEOP;
  int good_in_safeop = 0;
  int64_t phase_start = now_ns(), op_ns = 0, enabled_ns = 0, run_start = 0, stop_ramp_start = 0;
  double run_s = seconds, cmd = 0, stop_from = 0;
  int32_t hold_actual[EXPECTED_SLAVES] = {0}, final_actual[EXPECTED_SLAVES] = {0};
  int have_hold = 0, have_final = 0, stopped_by_signal = 0;
  uint16_t cw[EXPECTED_SLAVES] = {0};
  int64_t next = now_ns();
  while (phase != PH_DONE) {
    uint16_t al_request = 0;
    if (phase == PH_SAFEOP && good_in_safeop >= SAFEOP_WARMUP_CYCLES) {
      al_request = AL_OP;
      phase = PH_WAIT_OP;
      phase_start = now_ns();
    }
    int good = cycle_frame(al_request);
    int64_t t = now_ns();
    if (g_stats.consecutive_bad >= MAX_CONSECUTIVE_BAD)
      fail("%ld cycles in a row lost or with a wrong WKC (the last one %s)", g_stats.consecutive_bad,
           good < 0 ? "lost" : "with a wrong WKC");

    /* AL: every slave must stay in OP once there (a watchdog would drop one to SAFE-OP + 0x001B). */
    if (good > 0 && phase >= PH_WAIT_OP) {
      int all_op = 1;
      for (int i = 0; i < EXPECTED_SLAVES; ++i) {
        if (g_al[i] & AL_ERROR)
          fail("slave %d in %s with error, AL status code 0x%04X (%s)", i + 1, al_state_text(g_al[i]), g_al_code[i],
               al_code_text(g_al_code[i]));
        if ((g_al[i] & 0x0F) == AL_OP) continue;
        all_op = 0;
        if (phase > PH_WAIT_OP) fail("slave %d left OP: now %s", i + 1, al_state_text(g_al[i]));
      }
      if (phase == PH_WAIT_OP && all_op) {
        op_ns = t;
        fprintf(stderr, "foreign-master: all %d slaves in OP after %.3f s\n", EXPECTED_SLAVES, (op_ns - g_start_ns) / 1e9);
        phase = PH_ENABLE;
        phase_start = t;
      }
    }
    if (good > 0 && phase == PH_SAFEOP) ++good_in_safeop;
    if (phase == PH_WAIT_OP && t - phase_start > (int64_t)(STATE_TIMEOUT_S * 1e9))
      fail("no OP %.1f s after asking for it (slave 1 in %s)", STATE_TIMEOUT_S, al_state_text(g_al[0]));

    /* A signal: ramp down quickly from wherever we are, then the normal way out. */
    if (g_signal && !stopped_by_signal) {
      stopped_by_signal = 1;
      fprintf(stderr, "foreign-master: signal %d: stopping\n", (int)g_signal);
      if (phase == PH_RUN) {
        stop_from = cmd;
        stop_ramp_start = t;
      } else if (phase < PH_RUN) {
        phase = phase == PH_ENABLE ? PH_SHUTDOWN : PH_DONE;
        phase_start = t;
      }
    }

    /* Step 3: CiA 402, only in OP (outputs are applied in OP only). */
    if (phase == PH_ENABLE && good > 0) {
      int all_enabled = 1;
      for (int i = 0; i < EXPECTED_SLAVES; ++i) {
        enum drive_state s = drive_state(statusword(i));
        cw[i] = controlword_towards_enabled(s, cw[i]);
        set_outputs(i, cw[i], 0);
        if (s != DS_ENABLED || (int8_t)inputs_of(i)[TX_MODE_DISPLAY] != MODE_CSV) all_enabled = 0;
      }
      if (all_enabled) {
        enabled_ns = run_start = t;
        fprintf(stderr, "foreign-master: all drives Operation Enabled in CSV after %.3f s; running %.1f s at %ld counts/s\n",
                (t - g_start_ns) / 1e9, seconds, velocity);
        phase = PH_RUN;
      } else if (t - phase_start > (int64_t)(STATE_TIMEOUT_S * 1e9)) {
        for (int i = 0; i < EXPECTED_SLAVES; ++i)
          fprintf(stderr, "foreign-master: drive %d statusword 0x%04X mode %d error code 0x%04X\n", i + 1, statusword(i),
                  (int8_t)inputs_of(i)[TX_MODE_DISPLAY], get16(inputs_of(i) + TX_ERROR_CODE));
        fail("drives not in Operation Enabled %.1f s after OP", STATE_TIMEOUT_S);
      }
    } else if (phase == PH_RUN) {
      /* Step 3: the velocity profile over run_s: ramp up (20 %), hold (50 %), ramp down (20 %),
       * zero (10 %, so that the wheels are at rest when the drives are switched off). */
      double tau = (t - run_start) / 1e9, ramp = 0.2 * run_s, down_end = 0.9 * run_s;
      if (stop_ramp_start) {  /* stopping on a signal: down to 0 in 200 ms, then 100 ms at rest */
        double k = 1.0 - (t - stop_ramp_start) / 0.2e9;
        cmd = k > 0 ? stop_from * k : 0;
      } else if (tau < ramp) {
        cmd = velocity * tau / ramp;
      } else if (tau < down_end - ramp) {
        cmd = (double)velocity;
      } else if (tau < down_end) {
        if (!have_hold) {  /* the end of the hold: how well the drives followed */
          for (int i = 0; i < EXPECTED_SLAVES; ++i) hold_actual[i] = velocity_actual(i);
          have_hold = 1;
        }
        cmd = velocity * (down_end - tau) / ramp;
      } else {
        cmd = 0;
      }
      for (int i = 0; i < EXPECTED_SLAVES; ++i) {
        if (good > 0 && drive_state(statusword(i)) != DS_ENABLED)
          fail("drive %d left Operation Enabled: statusword 0x%04X, error code 0x%04X", i + 1, statusword(i),
               get16(inputs_of(i) + TX_ERROR_CODE));
        set_outputs(i, 0x000F, (int32_t)(cmd >= 0 ? cmd + 0.5 : cmd - 0.5));
      }
      if (tau >= run_s || (stop_ramp_start && t - stop_ramp_start >= 300000000LL)) {
        for (int i = 0; i < EXPECTED_SLAVES; ++i) final_actual[i] = velocity_actual(i);
        have_final = 1;
        phase = PH_SHUTDOWN;
        phase_start = t;
      }
    } else if (phase == PH_SHUTDOWN || phase == PH_DISABLE) {
      /* Step 4: controlword 6 (shutdown → ready to switch on), then 0 (→ switch on disabled). */
      enum drive_state want = phase == PH_SHUTDOWN ? DS_READY : DS_SWITCH_ON_DISABLED;
      int all_there = good > 0;
      for (int i = 0; i < EXPECTED_SLAVES; ++i) {
        set_outputs(i, phase == PH_SHUTDOWN ? 0x0006 : 0x0000, 0);
        if (drive_state(statusword(i)) != want) all_there = 0;
      }
      if (all_there || t - phase_start > 500000000LL) {
        if (!all_there) fprintf(stderr, "foreign-master: drives did not all report the step down in 0.5 s\n");
        phase = phase == PH_SHUTDOWN ? PH_DISABLE : PH_DONE;
        phase_start = t;
      }
    }

    /* Sleep to the next cycle start (absolute: no drift); cycles we overran are skipped. */
    next += CYCLE_NS;
    t = now_ns();
    while (next <= t) {
      next += CYCLE_NS;
      ++g_stats.overruns;
    }
    struct timespec ts = to_ts(next);
    while (clock_nanosleep(CLOCK_MONOTONIC, TIMER_ABSTIME, &ts, NULL) == EINTR) {}
  }

  /* Step 4: the slaves back to INIT, then the summary. */
  request_state(AL_INIT);
  fprintf(stderr, "foreign-master: longest round trip %.0f us; %ld replies came back after their cycle (discarded)\n",
          g_stats.max_round_trip_ns / 1e3, g_stats.stale);
  if (!stopped_by_signal && g_stats.cycles > 0 && (double)(g_stats.lost + g_stats.wkc_errors) > MAX_BAD_FRACTION * g_stats.cycles)
    fail("%ld lost frames and %ld WKC errors in %ld cycles: more than %.0f %%", g_stats.lost, g_stats.wkc_errors,
         g_stats.cycles, 100 * MAX_BAD_FRACTION);
  if (!stopped_by_signal && have_hold)
    for (int i = 0; i < EXPECTED_SLAVES; ++i)
      if (labs(hold_actual[i] - velocity) > TRACKING_TOLERANCE * labs(velocity) + 100)
        fail("drive %d velocity actual %d at the end of the hold, commanded %ld", i + 1, hold_actual[i], velocity);
  char op[80], hold[64], fin[64];
  if (!op_ns) snprintf(op, sizeof op, "OP not reached");
  else if (!enabled_ns) snprintf(op, sizeof op, "OP after %.3f s, drives not enabled", (op_ns - g_start_ns) / 1e9);
  else snprintf(op, sizeof op, "OP after %.3f s, Operation Enabled after %.3f s", (op_ns - g_start_ns) / 1e9,
                (enabled_ns - g_start_ns) / 1e9);
  printf("foreign-master: %d slaves, %s, %ld cycles, %ld lost, %ld wkc errors, %ld overruns, command %ld counts/s, "
         "velocity actual at end of hold %s, final velocity actual %s%s\n",
         EXPECTED_SLAVES, op, g_stats.cycles, g_stats.lost, g_stats.wkc_errors, g_stats.overruns, velocity,
         four_values(hold, sizeof hold, hold_actual, have_hold), four_values(fin, sizeof fin, final_actual, have_final),
         stopped_by_signal ? " (stopped by signal)" : "");
  fflush(stdout);
  close(g_link.fd);
  return 0;
}
